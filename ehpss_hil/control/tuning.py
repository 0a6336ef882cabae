"""Tuning constants of the adaptive layer (docs/design.md §5), as a frozen, YAML-loadable dataclass.

Units: rates in 1/s, times in s; ε-related values are normalized (dimensionless).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..schema import rng


@dataclass(frozen=True)
class ControlTuning:
    """Estimator, index and supervisor constants (defaults = docs/design.md §5).

    Every number has a finite range (``rng`` metadata, checked when loaded from YAML): the
    adaptive layer turns times into sample counts and squares the ε values. The fixed model
    tuples fill the DBC's model slots (:mod:`.controllers`: at most 2 spool and 3 position
    models); each limits pair is ``(low, high)`` with low < high (checked by the config).
    """

    #: NLMS contraction per millisecond; at most 1 (a full step), else (1 − g)^(Ts/1 ms) is complex
    nlms_gain_per_ms: float = field(default=0.2, metadata=rng(0.0, 1.0, lo_open=True))
    index_a1: float = field(default=1.0, metadata=rng(0.0, 1e3))
    index_a2: float = field(default=1.0, metadata=rng(0.0, 1e3))
    forgetting_1_s: float = field(default=10.0, metadata=rng(0.0, 1e4, lo_open=True))
    hysteresis: float = field(default=0.2, metadata=rng(0.0, 1.0))
    epsilon0: float = field(default=0.005, metadata=rng(0.0, 10.0))
    noise_margin_factor: float = field(default=2.0, metadata=rng(0.0, 1e3))
    dwell_s: float = field(default=0.005, metadata=rng(0.0, 60.0))
    #: a switch needs its condition to hold this long in a row for the same model (s)
    switch_confirm_s: float = field(default=0.01, metadata=rng(0.0, 1.0))
    warmup_s: float = field(default=0.03, metadata=rng(0.0, 60.0))
    min_theta_separation: float = field(default=0.02, metadata=rng(0.0, 10.0))
    guard_epsilon: float = field(default=0.4, metadata=rng(0.0, 10.0, lo_open=True))
    sensor_failed_below: float = field(default=0.15, metadata=rng(0.0, 1.0))
    anchor_rate_1_s: float = field(default=2.0, metadata=rng(0.0, 1e3))
    fixed_k_loe: tuple[float, ...] = field(
        default=(1.0, 0.5), metadata=rng(0.0, 1.5, lo_open=True, length=(1, 2))
    )
    fixed_k_dft: tuple[float, ...] = field(default=(1.0, 0.5, 0.0), metadata=rng(0.0, 2.5, length=(1, 3)))
    k_loe_limits: tuple[float, ...] = field(default=(0.05, 1.5), metadata=rng(0.0, 1.5, length=(2, 2)))
    k_dft_limits: tuple[float, ...] = field(default=(0.0, 2.5), metadata=rng(0.0, 2.5, length=(2, 2)))
    #: channel excitation gate: no switch and no adaptation while |φ| < excitation_floor·S
    #: (fraction of S)
    excitation_floor: float = field(default=0.03, metadata=rng(0.0, 1.0))
    #: NLMS regularization c = (nlms_c_fraction·S)² (≥ 1e-4: a vanishing c divides by φ² = 0)
    nlms_c_fraction: float = field(default=0.03, metadata=rng(1e-4, 10.0))
    #: position-channel guard: when even the best position model leaves a normalized residual
    #: above this, the sensor is not trusted (feedback from the model position x̂, no anchoring)
    position_guard_epsilon: float = field(default=0.02, metadata=rng(0.0, 10.0, lo_open=True))
    #: bumpless return from model-position feedback to the sensor: the sensor's share of the
    #: fed-back position ramps from 0 to 1 over this time (s); 0 = switch at once
    feedback_blend_s: float = field(default=0.02, metadata=rng(0.0, 60.0))
    #: a guard is released when the best J falls below guard_release·J_max
    guard_release: float = field(default=0.25, metadata=rng(0.0, 1.0, lo_open=True))
    #: mmac: attribute a position-channel gain change to the flow gain k_Q when the load pressure
    #: says so (control/flowgain.py): switch, log-likelihood threshold, evidence window (s)
    flow_gain_test: bool = True
    flow_gain_threshold: float = field(default=8.0, metadata=rng(0.0, 1e6, lo_open=True))
    flow_gain_window_s: float = field(default=0.5, metadata=rng(0.0, 60.0, lo_open=True))
    #: … the smallest |θ_prod − 1| taken as a deviation to attribute; the evidence the window
    #: must hold before a decision (s); the increment excitation gate (fraction of the nominal
    #: M-sample increment K_c·S·M·Ts)
    flow_gain_min_deviation: float = field(default=0.05, metadata=rng(0.0, 1.0, lo_open=True))
    flow_gain_min_evidence_s: float = field(default=0.03, metadata=rng(0.0, 10.0))
    flow_gain_excitation: float = field(default=0.1, metadata=rng(0.0, 1.0))
    #: … H_D (the sensor's) is decided only at Λ < −flow_gain_sensor_threshold: a flow-gain loss
    #: compensated as a drift moves the piston by (1 − k_Q)·x_d, a drift compensated as a
    #: flow-gain loss costs no more than the plain PI loop, so the sensor needs more evidence
    flow_gain_sensor_threshold: float = field(default=12.0, metadata=rng(0.0, 1e6, lo_open=True))
    #: mmac do-no-harm monitor (control/monitor.py): a rule must fire this long in a row to fall
    #: back to nominal compensation; the fallback ends after this long without any rule firing (s)
    monitor_confirm_s: float = field(default=0.003, metadata=rng(0.0, 1.0))
    monitor_reengage_s: float = field(default=0.05, metadata=rng(0.0, 10.0))
    #: the do-no-harm monitor: a sensor whose increments follow the spool integral with at least
    #: this gain is not failed
    monitor_sensor_alive: float = field(default=0.5, metadata=rng(0.0, 2.5))
    #: a sensor held off (declared failed: θ̂_D below ``sensor_failed_below``; guarded; dead) is
    #: fed back again only when, read through θ̂_D, it is within this of the model position x̂
    #: (fraction of the reference amplitude), or its increments follow the spool: an estimate
    #: that merely crossed the threshold, or a released guard, is not a sensor that came back
    sensor_return_gap: float = field(default=0.5, metadata=rng(0.0, 1e3, lo_open=True))
    #: the position-increment regression (mmac-paper, smac, and mmac's flow-gain product): its
    #: window (samples)
    increment_window: int = field(default=10, metadata=rng(1, 1000))
