"""The EHPSS plant stepped at a fixed sample time with exact ZOH (one implementation, used by the
emulator process and the lockstep simulator alike)."""

from __future__ import annotations

import typing
from collections.abc import Hashable

import numpy as np

from .discretize import Matrix, ZohCache
from .faults import FaultState
from .model import ACC, POS, SPOOL, load_pressure_pa, plant_matrices
from .params import Params


class PlantStepper:
    """Plant state ``[ẍ, ẋ, x, ẋ_v, x_v]`` advanced by one sample per :meth:`step`.

    The input current is held constant over the sample (ZOH). The ZOH map is cached by
    ``(k_loe, k_q)``, so a fault change costs one ``expm`` and steady running costs a 5×5 matvec.
    """

    def __init__(self, params: Params, ts_s: float) -> None:
        self.params = params
        self.ts_s = ts_s
        self._zoh = ZohCache(self._continuous, ts_s)
        self.state = np.zeros(5)
        self._ad: Matrix
        self._bd: Matrix
        self._key: Hashable = None
        self.faults = FaultState()
        self._select(self.faults)

    def _continuous(self, key: Hashable) -> tuple[Matrix, Matrix]:
        k_loe, k_q = typing.cast(tuple[float, float], key)
        return plant_matrices(self.params.plant, k_loe, k_q)

    def _select(self, faults: FaultState) -> None:
        key = faults.dynamics_key
        if key != self._key:
            self._ad, bd = self._zoh.get(key)
            self._bd = bd[:, 0].copy()
            self._key = key

    def reset(self) -> None:
        """Back to rest at the origin, fault-free."""
        self.state[:] = 0.0
        self.set_faults(FaultState())

    def set_faults(self, faults: FaultState) -> None:
        """Apply new fault values from the next sample on."""
        self.faults = faults
        self._select(faults)

    def step(self, current_a: float) -> float:
        """Advance one sample with ``current_a`` held; returns the applied (saturated) current (A)."""
        lim = self.faults.current_limit_a
        applied = min(max(current_a, -lim), lim)
        self.state = self._ad @ self.state + self._bd * applied
        return applied

    @property
    def position_m(self) -> float:
        """True piston position x (m)."""
        return float(self.state[POS])

    @property
    def spool_actual_m(self) -> float:
        """Actual spool displacement k_loe·x_v (m): what the spool LVDT measures (eq 8)."""
        return float(self.faults.k_loe * self.state[SPOOL])

    @property
    def spool_commanded_m(self) -> float:
        """Spool displacement the valve dynamics produce from the current, x_v (m)."""
        return float(self.state[SPOOL])

    @property
    def load_pressure_pa(self) -> float:
        """Load pressure P_L = m·ẍ/A_h (Pa)."""
        return load_pressure_pa(self.params.plant, float(self.state[ACC]))
