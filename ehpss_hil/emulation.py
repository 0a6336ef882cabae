"""The emulated EHPSS, independent of any bus or clock: fault schedule, plant, sensors, noise.

One implementation, used by the ``firmware-sim`` program, the lockstep simulator, sample logs and
the reliability trials (it lives here, not in the program, so that none of them imports a program).

Sample convention (index k, period Ts): :meth:`PlantEmulation.measure` gives the sensor sample
y[k] of the state x[k] with the faults in force at k; :meth:`PlantEmulation.advance` applies a
coil current held over [k, k+1) and moves to k+1. A loop with a one-sample transport delay applies
over [k, k+1) the command computed from y[k−1].
"""

from __future__ import annotations

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


class _Stream:
    """Seeded random numbers drawn in blocks (cheap per sample, reproducible for any length)."""

    def __init__(self, seed: int, stream: int, kind: str) -> None:
        self._rng = np.random.default_rng([seed, stream])
        self._kind = kind
        self._buf: list[float] = []
        self._i = 0

    def next(self) -> float:
        i = self._i
        if i >= len(self._buf):
            block = self._rng.standard_normal(_BLOCK) if self._kind == "normal" else self._rng.random(_BLOCK)
            self._buf = block.tolist()  # Python floats: indexing a list is cheaper than an array
            i = 0
        self._i = i + 1
        return self._buf[i]


class PlantEmulation:
    """Plant + sensors + the scenario's fault schedule, advanced one sample at a time.

    The plant is the scenario's (``plant:`` section, :func:`~.physics.plant.make_plant`) over
    ``plant_params``, the emulator's params.yaml plant (default: ``params.plant``); ``params``
    also gives the PI gains that scale a disturbance entering at the valve.
    """

    def __init__(self, params: Params, scenario: Scenario, plant_params: PlantParams | None = None) -> None:
        self.params = params
        self.scenario = scenario
        self.ts_s = scenario.sample_time_s
        base = plant_params if plant_params is not None else params.plant
        self.plant: Plant = make_plant(scenario.plant, base, self.ts_s)
        self._timeline = scenario.fault_timeline()
        g = params.controller
        self._valve_dist_gain_a_per_m = g.k_f * g.k_a * g.k_p
        self.reset()

    def reset(self) -> None:
        """Back to k = 0, at rest, with fresh (identically seeded) random streams."""
        seed = self.scenario.seed
        self._noise = [_Stream(seed, i, "normal") for i in range(3)]
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
        if self.scenario.disturbance.enters == "sensor":
            y -= self._disturbance_m()
        return y

    def measure(self) -> SensorSample:
        """The sensor sample y[k] (draws this sample's noise; call exactly once per sample)."""
        nz = self.scenario.noise
        s_pos, s_spool, s_p = self._noise
        n_pos, n_spool, n_p = s_pos.next(), s_spool.next(), s_p.next()
        if self.plant.faults.stuck:
            pos = self._stuck_value_m
        else:
            pos = self._measured_position() + nz.position_m * n_pos
        return SensorSample(
            k=self.k,
            t_s=self.k * self.ts_s,
            position_m=pos,
            spool_m=self.plant.spool_actual_m + nz.spool_m * n_spool,
            load_pressure_pa=self.plant.load_pressure_pa + nz.pressure_pa * n_p,
            coil_current_a=self.plant.coil_current_a,
            true_position_m=self.plant.position_m,
            true_spool_m=self.plant.spool_actual_m,
            faults=self.plant.faults,
            current_saturated=self._saturated,
        )

    def frame_lost(self, direction: int) -> bool:
        """Seeded loss draw for this sample: direction 0 = sensor frames (probability
        ``loss.sensor``), 1 = command frames (``loss.command``). Each direction has its own
        stream, drawn once per call whatever the probability (the streams stay on the sample
        grid, so a scenario without the directional keys gives the same draws as before)."""
        p = self.loss.sensor if direction == 0 else self.loss.command
        return self._loss[direction].next() < p

    # ---- dynamics ---------------------------------------------------------------------------
    def advance(self, current_a: float) -> float:
        """Hold ``current_a`` (A) over [k, k+1), step to k+1; returns the applied current (A)."""
        i = current_a
        if self.scenario.disturbance.enters == "valve":
            i += self._valve_dist_gain_a_per_m * self._disturbance_m()
        applied = self.plant.step(i)
        self._saturated = applied != i
        self.k += 1
        self._apply_schedule()
        return applied
