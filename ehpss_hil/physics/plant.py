"""The emulated plant behind one :class:`Plant` protocol, stepped at a fixed sample time.

:class:`LinearPlant` is the paper's eq 39 plant with exact ZOH; the nonlinear valve-controlled
cylinder lives in :mod:`.hydraulics`, the user's FMU in :mod:`.fmuplant`. :func:`make_plant`
builds the one a scenario's ``plant:`` section asks for. The emulation
(:mod:`ehpss_hil.emulation`), and through it the emulator process, the lockstep simulator and
the CiA 408 node, only ever see the protocol.
"""

from __future__ import annotations

import typing
from collections.abc import Hashable
from pathlib import Path
from typing import Protocol

import numpy as np

from .discretize import Matrix, ZohCache
from .faults import FaultState
from .fmumap import ACTUATOR_FAULTS
from .model import ACC, POS, SPOOL, SPOOL_VEL, load_pressure_pa, plant_matrices
from .params import Params, PlantParams
from .plantspec import PlantSpec


class Plant(Protocol):
    """What the emulation needs of a plant: one sample per :meth:`step` with the coil current
    held (A), the faults in force, and what the sensors measure (SI): each output on its own
    (the properties) or all four in one call (:meth:`outputs`, what the emulation reads every
    sample)."""

    ts_s: float
    faults: FaultState
    #: the actuator faults (FaultState fields of :data:`~.fmumap.ACTUATOR_FAULTS`) the plant
    #: models; the others must stay 1 (an FMU models those its ``fmu_map`` names)
    modelled_faults: frozenset[str]

    def reset(self) -> None:
        """Back to rest at the origin (valve centred, piston centred), fault-free."""

    def set_faults(self, faults: FaultState) -> None:
        """Apply new fault values from the next sample on."""

    def step(self, current_a: float) -> float:
        """Advance one sample with ``current_a`` held; returns the applied (limited) current (A)."""

    def outputs(self) -> tuple[float, float, float, float]:
        """``(position_m, spool_actual_m, load_pressure_pa, coil_current_a)`` now, in one call:
        the same values as the four properties (m, m, Pa, A)."""

    @property
    def position_m(self) -> float:
        """True piston position x (m)."""

    @property
    def spool_actual_m(self) -> float:
        """Actual spool displacement (m): what the spool LVDT measures."""

    @property
    def spool_commanded_m(self) -> float:
        """Spool displacement the valve dynamics produce from the current, before k_LOE (m)."""

    @property
    def load_pressure_pa(self) -> float:
        """Load pressure (Pa): what the pressure sensor measures."""

    @property
    def coil_current_a(self) -> float:
        """Coil current the valve electronics echo for the last sample (A)."""


#: the actuator faults the built-in plants model: all
ALL_ACTUATOR_FAULTS = frozenset(ACTUATOR_FAULTS)


class LinearPlant:
    """Plant state ``[ẍ, ẋ, x, ẋ_v, x_v]`` advanced by one sample per :meth:`step`.

    The input current is held constant over the sample (ZOH). The ZOH map is cached by
    ``(k_loe, k_q)``, so a fault change costs one ``expm``; steady running is the 5×5 map written
    out on Python floats (about half the cost of a numpy matvec of this size).
    """

    __slots__ = (
        "_c",
        "_key",
        "_p_per_acc",
        "_rows_stop",
        "_s",
        "_stop_m",
        "_stroke_m",
        "_u",
        "_zoh",
        "_zoh_stop",
        "faults",
        "modelled_faults",
        "plant_params",
        "ts_s",
    )

    def __init__(self, plant: PlantParams, ts_s: float) -> None:
        self.plant_params = plant
        self.ts_s = ts_s
        self._zoh = ZohCache(self._continuous, ts_s)
        #: the piston [ẍ, ẋ, x] driven by a held spool x_v, for samples the spool spends on its stop
        self._zoh_stop = ZohCache(self._continuous_piston, ts_s)
        self._s: list[float] = [0.0] * 5
        #: the free map's rows [A_d row i, B_d row i], i = 0…4, one after the other
        self._c: tuple[float, ...] = ()
        self._rows_stop: tuple[tuple[float, ...], ...] = ()
        self._key: Hashable = None
        self._u = 0.0
        self.modelled_faults = ALL_ACTUATOR_FAULTS
        self.faults = FaultState()
        self._stroke_m = plant.spool_stroke_m
        self._p_per_acc = load_pressure_pa(plant, 1.0)
        self.set_faults(self.faults)

    @property
    def state(self) -> Matrix:
        """The state ``[ẍ, ẋ, x, ẋ_v, x_v]`` (a copy)."""
        return np.array(self._s)

    def _continuous(self, key: Hashable) -> tuple[Matrix, Matrix]:
        k_loe, k_q = typing.cast(tuple[float, float], key)
        return plant_matrices(self.plant_params, k_loe, k_q)

    def _continuous_piston(self, key: Hashable) -> tuple[Matrix, Matrix]:
        a, _ = self._continuous(key)
        return a[:SPOOL_VEL, :SPOOL_VEL], a[:SPOOL_VEL, SPOOL : SPOOL + 1]

    def _select(self, faults: FaultState) -> None:
        key = faults.dynamics_key
        if key != self._key:
            ad, bd = self._zoh.get(key)
            # each row: the state coefficients, then the input's (step unpacks them at once)
            self._c = tuple(c for i in range(5) for c in (*map(float, ad[i]), float(bd[i, 0])))
            ad, bd = self._zoh_stop.get(key)
            self._rows_stop = tuple((*map(float, ad[i]), float(bd[i, 0])) for i in range(3))
            self._key = key

    def reset(self) -> None:
        """Back to rest at the origin, fault-free."""
        self._s = [0.0] * 5
        self._u = 0.0
        self.set_faults(FaultState())

    def set_faults(self, faults: FaultState) -> None:
        """Apply new fault values from the next sample on."""
        self.faults = faults
        self._stop_m = self._stroke_m / faults.k_loe  # where x_v stops (m)
        self._select(faults)

    def step(self, current_a: float) -> float:
        """Advance one sample with ``current_a`` held; returns the applied (saturated) current (A).

        The spool stops at its stroke (an inelastic stop): when the free step would carry the
        actual spool ``k_LOE·x_v`` past ±``spool_stroke_m``, the spool ends the sample on the
        stop at rest and the piston is stepped with the spool held there over the whole sample
        (the valve is fast against Ts: it reaches the stop early in the sample)."""
        lim = self.faults.current_limit_a
        u = -lim if current_a < -lim else lim if current_a > lim else current_a  # min(max(…)) inline
        self._u = u
        s0, s1, s2, s3, s4 = self._s
        # the coefficients unpacked at once (one unpack instead of 30 subscripts: every sample)
        (a00, a01, a02, a03, a04, b0, a10, a11, a12, a13, a14, b1, a20, a21, a22, a23, a24, b2,
         a30, a31, a32, a33, a34, b3, a40, a41, a42, a43, a44, b4) = self._c  # fmt: skip
        xv = a40 * s0 + a41 * s1 + a42 * s2 + a43 * s3 + a44 * s4 + b4 * u
        stop = self._stop_m
        if -stop <= xv <= stop:
            self._s = [
                a00 * s0 + a01 * s1 + a02 * s2 + a03 * s3 + a04 * s4 + b0 * u,
                a10 * s0 + a11 * s1 + a12 * s2 + a13 * s3 + a14 * s4 + b1 * u,
                a20 * s0 + a21 * s1 + a22 * s2 + a23 * s3 + a24 * s4 + b2 * u,
                a30 * s0 + a31 * s1 + a32 * s2 + a33 * s3 + a34 * s4 + b3 * u,
                xv,
            ]
        else:
            held = stop if xv > 0.0 else -stop
            q0, q1, q2 = self._rows_stop
            self._s = [
                q0[0] * s0 + q0[1] * s1 + q0[2] * s2 + q0[3] * held,
                q1[0] * s0 + q1[1] * s1 + q1[2] * s2 + q1[3] * held,
                q2[0] * s0 + q2[1] * s1 + q2[2] * s2 + q2[3] * held,
                0.0,
                held,
            ]
        return u

    def outputs(self) -> tuple[float, float, float, float]:
        """``(x, k_loe·x_v, P_L, applied current)`` (m, m, Pa, A): the four properties below in
        one call (the emulation reads them every sample), expression for expression."""
        s = self._s
        return s[POS], self.faults.k_loe * s[SPOOL], self._p_per_acc * s[ACC], self._u

    @property
    def position_m(self) -> float:
        """True piston position x (m)."""
        return self._s[POS]

    @property
    def spool_actual_m(self) -> float:
        """Actual spool displacement k_loe·x_v (m): what the spool LVDT measures (eq 8)."""
        return self.faults.k_loe * self._s[SPOOL]

    @property
    def spool_commanded_m(self) -> float:
        """Spool displacement the valve dynamics produce from the current, x_v (m)."""
        return self._s[SPOOL]

    @property
    def load_pressure_pa(self) -> float:
        """Load pressure P_L = m·ẍ/A_h (Pa)."""
        return self._p_per_acc * self._s[ACC]

    @property
    def coil_current_a(self) -> float:
        """The current applied over the last sample (A): the amplifier's echo."""
        return self._u


class PlantStepper(LinearPlant):
    """The linear plant of a full :class:`Params` (the name tools and tests used before
    :class:`Plant`; new code builds :class:`LinearPlant` from ``params.plant``)."""

    def __init__(self, params: Params, ts_s: float) -> None:
        super().__init__(params.plant, ts_s)


def make_plant(spec: PlantSpec, base: PlantParams, ts_s: float) -> Plant:
    """The plant a scenario's ``plant:`` section asks for: ``base`` (the emulator's params.yaml
    plant) with the section's lumped keys, linear or nonlinear (:mod:`.hydraulics`), or the
    section's FMU (:mod:`.fmuplant`; ``base`` unused: the FMU carries its parameters)."""
    if spec.model == "fmu":
        from .fmuplant import FmuPlant  # fmpy: only for an FMU plant

        assert spec.fmu_map is not None
        return FmuPlant(Path(spec.path), spec.fmu_map, ts_s)
    plant = spec.plant_params(base)
    if spec.model == "nonlinear":
        from .hydraulics import NonlinearPlant, derive

        return NonlinearPlant(derive(plant, spec), plant, ts_s)
    return LinearPlant(plant, ts_s)
