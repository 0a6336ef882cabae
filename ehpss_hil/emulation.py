"""The emulated EHPSS, independent of any bus or clock: fault schedule, plant, sensors, noise.

One implementation, used by the ``firmware-sim`` program, the lockstep simulator, sample logs and
the reliability trials (it lives here, not in the program, so that none of them imports a program).

Sample convention (index k, period Ts): :meth:`PlantEmulation.measure` gives the sensor sample
y[k] of the state x[k] with the faults in force at k; :meth:`PlantEmulation.advance` applies a
coil current held over [k, k+1) and moves to k+1. A loop with a one-sample transport delay applies
over [k, k+1) the command computed from y[k−1].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .errors import InjectError
from .physics.faults import FaultState
from .physics.fmumap import ACTUATOR_FAULTS
from .physics.params import Params, PlantParams
from .physics.plant import Plant, make_plant
from .scenario import FrameLoss, Scenario

_BLOCK = 4096


@dataclass(slots=True)
class SensorSample:
    """What the sensors report at sample k (SI), plus the truth kept for metrics.

    ``coil_current_a`` is the current applied over the previous sample (the amplifier's echo).
    """

    k: int
    t_s: float
    position_m: float
    spool_m: float
    load_pressure_pa: float
    coil_current_a: float
    true_position_m: float
    true_spool_m: float
    faults: FaultState
    current_saturated: bool


#: :class:`SensorSample`'s fields as a tuple, in its order (:meth:`PlantEmulation.sample`)
SampleValues = tuple[int, float, float, float, float, float, float, float, FaultState, bool]


class _Stream:
    """Seeded random numbers drawn in blocks (cheap per sample, reproducible for any length)."""

    __slots__ = (
        "_buf",
        "_i",
        "_kind",
        "_n",
        "_rng",
    )

    def __init__(self, seed: int, stream: int, kind: str) -> None:
        self._rng = np.random.default_rng([seed, stream])
        self._kind = kind
        self._buf: list[float] = []
        self._n = 0
        self._i = 0

    def block(self) -> np.ndarray:
        """The next :data:`_BLOCK` draws (standard normal or uniform on [0, 1))."""
        return self._rng.standard_normal(_BLOCK) if self._kind == "normal" else self._rng.random(_BLOCK)

    def next(self) -> float:
        i = self._i
        if i >= self._n:
            self._buf = self.block().tolist()  # Python floats: indexing a list is cheaper than an array
            self._n = len(self._buf)
            i = 0
        self._i = i + 1
        return self._buf[i]


class _SensorNoise:
    """The noise of the position, spool and pressure sensors (m, m, Pa): three seeded standard
    normal streams scaled by their standard deviations, one tuple per sample. The streams are
    drawn and scaled a block at a time (the same products as scaling each draw alone)."""

    __slots__ = (
        "_buf",
        "_i",
        "_n",
        "_sigmas",
        "_streams",
    )

    def __init__(self, seed: int, sigmas: tuple[float, float, float]) -> None:
        self._streams = [_Stream(seed, i, "normal") for i in range(3)]
        self._sigmas = sigmas
        self._buf: list[tuple[float, float, float]] = []
        self._n = 0
        self._i = 0

    def next(self) -> tuple[float, float, float]:
        i = self._i
        if i >= self._n:
            cols = [(sd * st.block()).tolist() for st, sd in zip(self._streams, self._sigmas, strict=True)]
            self._buf = list(zip(*cols, strict=True))
            self._n = len(self._buf)
            i = 0
        self._i = i + 1
        return self._buf[i]


class PlantEmulation:
    """Plant + sensors + the scenario's fault schedule, advanced one sample at a time.

    The plant is the scenario's (``plant:`` section, :func:`~.physics.plant.make_plant`) over
    ``plant_params``, the emulator's params.yaml plant (default: ``params.plant``); ``params``
    also gives the PI gains that scale a disturbance entering at the valve.
    """

    __slots__ = (
        "_due_k",
        "_loss",
        "_next_event",
        "_noise",
        "_override",
        "_saturated",
        "_scheduled",
        "_sensor_dist",
        "_sigmas",
        "_stuck_value_m",
        "_timeline",
        "_valve_dist",
        "_valve_dist_gain_a_per_m",
        "k",
        "loss",
        "params",
        "plant",
        "scenario",
        "ts_s",
    )

    def __init__(self, params: Params, scenario: Scenario, plant_params: PlantParams | None = None) -> None:
        self.params = params
        self.scenario = scenario
        self.ts_s = scenario.sample_time_s
        base = plant_params if plant_params is not None else params.plant
        self.plant: Plant = make_plant(scenario.plant, base, self.ts_s)
        self._timeline = scenario.fault_timeline()
        g = params.controller
        self._valve_dist_gain_a_per_m = g.k_f * g.k_a * g.k_p
        dist = scenario.disturbance
        #: the disturbance subtracted from the measured position (None: none there; a "none"
        #: disturbance is 0 m, and y − 0.0 is y)
        self._sensor_dist = dist if dist.enters == "sensor" and dist.kind != "none" else None
        self._valve_dist = dist.enters == "valve"
        nz = scenario.noise
        self._sigmas = (nz.position_m, nz.spool_m, nz.pressure_pa)
        self.reset()

    def reset(self) -> None:
        """Back to k = 0, at rest, with fresh (identically seeded) random streams."""
        seed = self.scenario.seed
        self._noise = _SensorNoise(seed, self._sigmas)
        self._loss = [_Stream(seed, 10 + i, "uniform") for i in range(2)]
        self.plant.reset()
        self.k = 0
        self._next_event = 0
        self.loss = self.scenario.initial_loss
        self._override: dict[str, float | bool] = {}
        self._stuck_value_m = 0.0
        self._saturated = False
        self._apply_schedule()

    # ---- faults -----------------------------------------------------------------------------
    def _apply_schedule(self) -> None:
        tl = self._timeline
        changed = False
        while self._next_event < len(tl) and tl[self._next_event][0] <= self.k:
            _, faults, loss = tl[self._next_event]
            self._scheduled = faults
            self.loss = loss
            self._next_event += 1
            changed = True
        #: the sample of the next scheduled event (:meth:`advance` looks no further before it)
        self._due_k = tl[self._next_event][0] if self._next_event < len(tl) else math.inf
        if changed:
            self._set(replace(self._scheduled, **self._override))  # type: ignore[arg-type]

    def _set(self, faults: FaultState) -> None:
        if faults.stuck and not self.plant.faults.stuck:
            self._stuck_value_m = self._measured_position()
        self.plant.set_faults(faults)

    def inject(self, **values: float | bool) -> FaultState:
        """Set fault values at run time (FAULT_INJECT); they override the schedule until cleared.

        Keys: ``k_loe``, ``k_q``, ``k_dft``, ``position_bias_m``, ``stuck``, ``current_limit_a``;
        ``frame_loss`` sets the loss probability of both directions (until the next scheduled
        loss change). Returns the new fault state; InjectError for an actuator fault the plant
        does not model (:attr:`~.physics.plant.Plant.modelled_faults`).
        """
        gone = [k for k in ACTUATOR_FAULTS if k in values and k not in self.plant.modelled_faults]
        if gone:
            raise InjectError(f"the plant does not model {gone[0]} (an FMU without fmu_map.{gone[0]})")
        if "frame_loss" in values:
            p = float(values.pop("frame_loss"))
            self.loss = FrameLoss(p, p)
        self._override.update(values)
        self._set(replace(self.plant.faults, **values))  # type: ignore[arg-type]
        return self.plant.faults

    def clear_injected(self) -> FaultState:
        """Drop every run-time override; the scheduled faults apply again."""
        self._override.clear()
        self._set(self._scheduled)
        return self.plant.faults

    @property
    def faults(self) -> FaultState:
        """The fault state in force at the current sample."""
        return self.plant.faults

    # ---- sensors ----------------------------------------------------------------------------
    def _disturbance_m(self) -> float:
        return self.scenario.disturbance.value_m(self.k * self.ts_s)

    def _measured_position(self) -> float:
        f = self.plant.faults
        y = f.k_dft * self.plant.position_m + f.position_bias_m
        if self._sensor_dist is not None:
            y -= self._sensor_dist.value_m(self.k * self.ts_s)
        return y

    def measure(self) -> SensorSample:
        """The sensor sample y[k] (draws this sample's noise; call exactly once per sample)."""
        return SensorSample(*self.sample())

    def sample(self) -> SampleValues:
        """:meth:`measure`'s values as a plain tuple, in :class:`SensorSample`'s field order
        (the lockstep simulator unpacks it every sample: no object built, no attribute read). A
        subclass that rewrites :meth:`measure` (firmware-sim's miswired emulation) rewrites
        only what :meth:`measure` returns.

        The plant's outputs are read in one call (this runs every sample of every simulation)."""
        noise = self._noise  # _SensorNoise.next written out (once a sample)
        i = noise._i
        if i < noise._n:
            noise._i = i + 1
            e_pos, e_spool, e_p = noise._buf[i]
        else:
            e_pos, e_spool, e_p = noise.next()
        plant, k = self.plant, self.k
        f = plant.faults
        x, spool, p_l, echo = plant.outputs()
        if f.stuck:
            pos = self._stuck_value_m
        else:
            pos = f.k_dft * x + f.position_bias_m
            if self._sensor_dist is not None:
                pos -= self._sensor_dist.value_m(k * self.ts_s)
            pos += e_pos
        return (k, k * self.ts_s, pos, spool + e_spool, p_l + e_p, echo, x, spool, f, self._saturated)

    def frame_lost(self, direction: int) -> bool:
        """Seeded loss draw for this sample: direction 0 = sensor frames (probability
        ``loss.sensor``), 1 = command frames (``loss.command``). Each direction has its own
        stream, drawn once per call whatever the probability (the streams stay on the sample
        grid, so a scenario without the directional keys gives the same draws as before)."""
        p = self.loss.sensor if direction == 0 else self.loss.command
        st = self._loss[direction]  # _Stream.next written out: twice a sample in a simulation
        i = st._i
        if i >= st._n:
            return st.next() < p
        st._i = i + 1
        return st._buf[i] < p

    def frame_losses(self) -> tuple[bool, bool]:
        """Both loss draws of this sample in one call: ``(frame_lost(0), frame_lost(1))``, the
        sensor frames' and the command frame's (the simulator draws both every sample; each
        direction has its own stream, so drawing them together gives the same draws)."""
        loss, (s0, s1) = self.loss, self._loss
        i = s0._i  # _Stream.next written out, as in frame_lost
        if i >= s0._n:
            sensor = s0.next() < loss.sensor
        else:
            s0._i = i + 1
            sensor = s0._buf[i] < loss.sensor
        i = s1._i
        if i >= s1._n:
            return sensor, s1.next() < loss.command
        s1._i = i + 1
        return sensor, s1._buf[i] < loss.command

    # ---- dynamics ---------------------------------------------------------------------------
    def advance(self, current_a: float) -> float:
        """Hold ``current_a`` (A) over [k, k+1), step to k+1; returns the applied current (A)."""
        i = current_a
        if self._valve_dist:
            i += self._valve_dist_gain_a_per_m * self._disturbance_m()
        applied = self.plant.step(i)
        self._saturated = applied != i
        self.k += 1
        if self.k >= self._due_k:
            self._apply_schedule()
        return applied
