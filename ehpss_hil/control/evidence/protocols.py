"""The contract of each piece of evidence, as the layer (and the pieces among themselves) use it.

A piece is replaced by another that keeps its protocol — a pressure test judged against a
plant with its uncertainty, say — without touching the layer's order or the loop. The shipped
implementations: :class:`.Increments`, :class:`.CreepEstimator`, :class:`.PressureTest`,
:class:`.SensorAttribution`, :class:`.StillSensor`, :class:`.HarmMonitor` (mypy checks each
against its protocol where the layer builds it).
"""

from __future__ import annotations

from typing import Protocol

from ..predictors import UnitPlantPredictor
from .monitor import FallbackReason


class CreepEvidence(Protocol):
    """The piston's velocity with the spool at null (m/s): near-null increments, or at start-up a
    joint fit with the gain."""

    rate_m_s: float

    @property
    def judged(self) -> bool: ...

    def reset(self) -> None: ...


class IncrementEvidence(Protocol):
    """θ_prod, the offset-free product k_DFT·k_Q from M-sample increments, and its companions."""

    theta_prod: float
    product_fresh: bool
    product_updated: bool
    product_settled: bool
    still_samples: int
    at_rest: bool
    spool_integral_m: float
    creep_integral_m: float

    @property
    def creep(self) -> CreepEvidence: ...

    @property
    def increment_window(self) -> int: ...

    @property
    def reading_noise_m(self) -> float: ...

    @property
    def since_jump_fit(self) -> tuple[float, float]: ...

    def reset(self) -> None: ...

    def restart_fit(self) -> None: ...

    def product(self, position_m: float, spool_m: float, samples: int = 1, excited: bool = True) -> float: ...

    def note_jump(self) -> None: ...

    def confirms(self, theta: float) -> bool: ...


class PressureEvidence(Protocol):
    """H_D (sensor) against H_Q (flow gain) from the load pressure; the sample clock steps its
    P_L :attr:`model`."""

    model: UnitPlantPredictor

    flow_fault: bool
    k_q: float
    sensor_decided: bool
    sensor_current: bool

    @property
    def k_base(self) -> float: ...

    @property
    def plant_seen(self) -> bool: ...

    @property
    def min_deviation(self) -> float: ...

    @property
    def sensor_favoured(self) -> bool: ...

    @property
    def sensor_gain(self) -> float: ...

    def compensated_product(self, theta_pos: float) -> float: ...

    def reset(self) -> None: ...

    def restart(self) -> None: ...

    def hold_off(self, samples: int) -> None: ...

    def forget_attribution(self) -> None: ...

    def decide_sensor(self, theta_prod: float) -> None: ...

    def withdraw_sensor(self) -> None: ...

    def update(
        self,
        current_a: float,
        pressure_pa: float,
        theta_l: float,
        theta_pos: float,
        theta_level: float = 1.0,
        healthy: bool = False,
        fresh: bool = True,
        updated: bool = True,
    ) -> float: ...


class JumpEvidence(Protocol):
    """May the position model in use be compensated as the sensor's (a jump of the reading, a
    change at rest, the pressure test's H_D)?"""

    by_jump: bool
    jump_gain: float
    jumped_since_guard: bool
    since_guard: int
    verified_gain: float

    def reset(self) -> None: ...

    def update(
        self, position_m: float, theta_d: float, model: int, guarded: bool, broken: bool, trusted: bool
    ) -> bool: ...


class StillEvidence(Protocol):
    """A sensor that stands still through a stop phase is dead: x̂ where the spool took the piston."""

    def reset(self) -> None: ...

    def update(self, at_stop: bool, spool_m: float, position_m: float, x_hat_m: float) -> float | None: ...


class OverlapEvidence(Protocol):
    """A spool overlap the plant has shown: the share of x̂'s in-band travel the piston makes."""

    gain: float

    def forget(self) -> None: ...

    def reset(self) -> None: ...

    def update(
        self, spool_m: float, position_m: float, healthy: bool, theta: float, noise_m: float
    ) -> bool: ...


class HarmEvidence(Protocol):
    """The do-no-harm monitor: the estimates in use against θ_prod and their clips."""

    fallback: bool
    fallbacks: int
    reason: FallbackReason

    def reset(self) -> None: ...

    def update(self, theta_used: float, theta_prod: float, prod_fresh: bool, at_limit: bool) -> bool: ...
