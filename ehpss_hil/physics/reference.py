"""The reference model y_m (paper eq 17): the fault-free eq 39 closed loop, exact ZOH at Ts."""

from __future__ import annotations

import numpy as np

from .discretize import zoh
from .model import closed_loop_matrices
from .params import Params


class ReferenceModel:
    """Discrete fault-free closed loop driven by the desired position r (m); output y_m (m).

    ``step(r)`` returns y_m at the current sample and then advances the state by one sample,
    i.e. ``y_m[k] = C x_m[k]``, ``x_m[k+1] = Ad x_m[k] + Bd r[k]``.
    """

    def __init__(self, params: Params, ts_s: float) -> None:
        a, b, c = closed_loop_matrices(params)
        self.ad, bd = zoh(a, b, ts_s)
        self.bd = bd[:, 0].copy()
        self.c = c[0].copy()
        self.state = np.zeros(6)

    def reset(self) -> None:
        """Back to rest."""
        self.state[:] = 0.0

    def step(self, r_m: float) -> float:
        """y_m now (m), then advance with input ``r_m`` held over the sample."""
        y = float(self.c @ self.state)
        self.state = self.ad @ self.state + self.bd * r_m
        return y

    def run(self, r_m: np.ndarray) -> np.ndarray:
        """y_m for a reference sequence (m), continuing from ``self.state``, which it advances:
        a long sequence run in parts gives what :meth:`simulate` gives on the whole of it."""
        x = self.state
        out = np.empty(len(r_m))
        for k, r in enumerate(r_m):
            out[k] = self.c @ x
            x = self.ad @ x + self.bd * r
        self.state = x
        return out

    def simulate(self, r_m: np.ndarray) -> np.ndarray:
        """y_m for a whole reference sequence (m), from rest; does not touch ``self.state``."""
        x = np.zeros(6)
        out = np.empty(len(r_m))
        for k, r in enumerate(r_m):
            out[k] = self.c @ x
            x = self.ad @ x + self.bd * r
        return out
