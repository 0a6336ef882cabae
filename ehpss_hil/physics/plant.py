"""The EHPSS plant stepped at a fixed sample time with exact ZOH (one implementation, used by the
emulator process and the lockstep simulator alike)."""

from __future__ import annotations

import typing
from collections.abc import Hashable

import numpy as np

from .discretize import Matrix, ZohCache
from .faults import FaultState
from .model import ACC, POS, SPOOL, SPOOL_VEL, load_pressure_pa, plant_matrices
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
        #: the piston [ẍ, ẋ, x] driven by a held spool x_v, for samples the spool spends on its stop
        self._zoh_stop = ZohCache(self._continuous_piston, ts_s)
        self.state = np.zeros(5)
        self._ad: Matrix
        self._bd: Matrix
        self._key: Hashable = None
        self.faults = FaultState()
        self._stroke_m = params.plant.spool_stroke_m
        self._select(self.faults)

    def _continuous(self, key: Hashable) -> tuple[Matrix, Matrix]:
        k_loe, k_q = typing.cast(tuple[float, float], key)
        return plant_matrices(self.params.plant, k_loe, k_q)

    def _continuous_piston(self, key: Hashable) -> tuple[Matrix, Matrix]:
        a, _ = self._continuous(key)
        return a[:SPOOL_VEL, :SPOOL_VEL], a[:SPOOL_VEL, SPOOL : SPOOL + 1]

    def _select(self, faults: FaultState) -> None:
        key = faults.dynamics_key
        if key != self._key:
            self._ad, bd = self._zoh.get(key)
            self._bd = bd[:, 0].copy()
            self._ad_stop, bd = self._zoh_stop.get(key)
            self._bd_stop = bd[:, 0].copy()
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
        """Advance one sample with ``current_a`` held; returns the applied (saturated) current (A).

        The spool stops at its stroke (an inelastic stop): when the free step would carry the
        actual spool ``k_LOE·x_v`` past ±``spool_stroke_m``, the spool ends the sample on the
        stop at rest and the piston is stepped with the spool held there over the whole sample
        (the valve is fast against Ts: it reaches the stop early in the sample)."""
        lim = self.faults.current_limit_a
        applied = min(max(current_a, -lim), lim)
        st = self._ad @ self.state + self._bd * applied
        stop = self._stroke_m / self.faults.k_loe
        xv = st[SPOOL]
        if xv > stop or xv < -stop:
            held = stop if xv > 0.0 else -stop
            st[:SPOOL_VEL] = self._ad_stop @ self.state[:SPOOL_VEL] + self._bd_stop * held
            st[SPOOL_VEL] = 0.0
            st[SPOOL] = held
        self.state = st
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
