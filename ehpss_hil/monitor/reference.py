"""x_d and y_m at the controller's sample index k, for the monitor.

The controller daemon starts its reference at its first ACTIVE cycle, so on the bus
``k = CycleCount − CycleCount₀`` (VALVE_CMD, 16-bit counter unwrapped, CycleCount₀ = the first
command with ``Enable = 1``) — the alignment the log reports use. x_d and y_m (the fault-free
reference model, exact ZOH, from rest at k = 0) are computed a chunk of samples ahead, never per
frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..physics.params import Params
from ..physics.reference import ReferenceModel
from ..scenario import Reference

#: samples of x_d and y_m computed at once (10 s at 1 kHz)
CHUNK_SAMPLES = 10_000


class ReferenceTrack:
    """x_d(k) and y_m(k) (m) of one reference at sample time ``ts_s`` (s), from rest at k = 0."""

    def __init__(self, reference: Reference, params: Params, ts_s: float, base_dir: Path | None = None):
        self.reference = reference
        self.ts_s = ts_s
        self.base_dir = base_dir
        self._model = ReferenceModel(params, ts_s)
        self._start = 0  # sample index of the chunk's first sample
        self._x_d = np.zeros(0)
        self._y_m = np.zeros(0)

    def at(self, k: int) -> tuple[float, float]:
        """``(x_d, y_m)`` at sample ``k`` ≥ 0 (m); only the current chunk is kept (a k before
        it recomputes from rest)."""
        if k < self._start:
            self._model.reset()
            self._start, self._x_d, self._y_m = 0, np.zeros(0), np.zeros(0)
        while k >= self._start + len(self._x_d):
            self._next_chunk()
        i = k - self._start
        return float(self._x_d[i]), float(self._y_m[i])

    def _next_chunk(self) -> None:
        k0 = self._start + len(self._x_d)
        self._x_d = self.reference.sample(np.arange(k0, k0 + CHUNK_SAMPLES) * self.ts_s, self.base_dir)
        self._y_m = np.array([self._model.step(float(r)) for r in self._x_d])
        self._start = k0
