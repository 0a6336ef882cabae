"""Every gate of the control layer, as a frozen, YAML-loadable dataclass (docs/control.md §3).

Each field carries, in its ``rng`` metadata, its range (checked when loaded from YAML), its unit
(``"1"``: dimensionless) and its origin: the derivation from the plant or the protocol, or the
measurement that fixed the value. :func:`gate_table` renders them as the table of
docs/control.md ("The gates"); a test keeps the two equal and the control modules free of
numeric constants of their own.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from ..schema import rng

_BENCH = "bench control rows (docs/control.md §8)"


@dataclass(frozen=True)
class ControlTuning:
    """Estimator, index, supervisor and evidence gates (defaults = docs/control.md §3).

    Times (``_s``) are turned into sample counts with the sample time; the fixed model tuples
    fill the DBC's model slots (:mod:`.controllers`: at most 2 spool and 3 position models);
    each limits pair is ``(low, high)`` with low < high (checked by the config).
    """

    # ---- banks and supervisors (docs/design.md §5) ----------------------------------------
    #: NLMS contraction per millisecond; at most 1 (a full step), else (1 − g)^(Ts/1 ms) is complex
    nlms_gain_per_ms: float = field(
        default=0.2,
        metadata=rng(
            0.0,
            1.0,
            lo_open=True,
            unit="1/ms",
            origin="docs/design.md §5: g = 1 − (1 − γ)^(Ts/1 ms) per sample",
        ),
    )
    index_a1: float = field(
        default=1.0, metadata=rng(0.0, 1e3, unit="1", origin="docs/design.md §5: the corrected eq 36 index")
    )
    index_a2: float = field(
        default=1.0, metadata=rng(0.0, 1e3, unit="1", origin="docs/design.md §5: the corrected eq 36 index")
    )
    forgetting_1_s: float = field(
        default=10.0,
        metadata=rng(
            0.0, 1e4, lo_open=True, unit="1/s", origin="docs/design.md §5: eq 36 index, 0.1 s of memory"
        ),
    )
    hysteresis: float = field(default=0.2, metadata=rng(0.0, 1.0, unit="1", origin="docs/design.md §5"))
    epsilon0: float = field(default=0.005, metadata=rng(0.0, 10.0, unit="1 (J)", origin="docs/design.md §5"))
    noise_margin_factor: float = field(
        default=2.0, metadata=rng(0.0, 1e3, unit="1", origin="switch above twice the noise floor; " + _BENCH)
    )
    dwell_s: float = field(default=0.005, metadata=rng(0.0, 60.0, unit="s", origin=_BENCH))
    #: a switch needs its condition to hold this long in a row for the same model (s)
    switch_confirm_s: float = field(
        default=0.01, metadata=rng(0.0, 1.0, unit="s", origin="one noisy sample makes no switch; " + _BENCH)
    )
    warmup_s: float = field(
        default=0.03, metadata=rng(0.0, 60.0, unit="s", origin="power-on faults compensated early; " + _BENCH)
    )
    min_theta_separation: float = field(default=0.02, metadata=rng(0.0, 10.0, unit="1", origin=_BENCH))
    guard_epsilon: float = field(
        default=0.4,
        metadata=rng(
            0.0,
            10.0,
            lo_open=True,
            unit="1 (mean-square residual)",
            origin="above fault transients; " + _BENCH,
        ),
    )
    sensor_failed_below: float = field(
        default=0.15,
        metadata=rng(0.0, 1.0, unit="1", origin="docs/design.md §5: below it the failed-sensor model"),
    )
    anchor_rate_1_s: float = field(
        default=2.0,
        metadata=rng(
            0.0, 1e3, unit="1/s", origin="removes an x̂ offset before the position FRA absorbs it; §3.4"
        ),
    )
    fixed_k_loe: tuple[float, ...] = field(
        default=(1.0, 0.5),
        metadata=rng(
            0.0,
            1.5,
            lo_open=True,
            length=(1, 2),
            unit="1",
            origin="docs/design.md §5: the paper's fixed models",
        ),
    )
    fixed_k_dft: tuple[float, ...] = field(
        default=(1.0, 0.5, 0.0),
        metadata=rng(0.0, 2.5, length=(1, 3), unit="1", origin="docs/design.md §5: the paper's fixed models"),
    )
    k_loe_limits: tuple[float, ...] = field(
        default=(0.05, 1.5),
        metadata=rng(0.0, 1.5, length=(2, 2), unit="1", origin="docs/design.md §5: the adaptive laws' clip"),
    )
    k_dft_limits: tuple[float, ...] = field(
        default=(0.0, 2.5),
        metadata=rng(0.0, 2.5, length=(2, 2), unit="1", origin="docs/design.md §5: the adaptive laws' clip"),
    )
    #: channel excitation gate: no switch and no adaptation while |φ| < excitation_floor·S
    excitation_floor: float = field(
        default=0.03, metadata=rng(0.0, 1.0, unit="1 (·S)", origin="RIA walk at rest; docs/control.md §3.1")
    )
    #: NLMS regularization c = (nlms_c_fraction·S)² (≥ 1e-4: a vanishing c divides by φ² = 0)
    nlms_c_fraction: float = field(
        default=0.03, metadata=rng(1e-4, 10.0, unit="1 (·S)", origin="0.1 crawled at zero crossings; §3.1")
    )
    #: position guard: even the best position model leaves a residual above this: x̂ carries the loop
    position_guard_epsilon: float = field(
        default=0.02,
        metadata=rng(0.0, 10.0, lo_open=True, unit="1 (J)", origin="while the FRA converges; §3.5"),
    )
    #: the sensor's share of the fed-back position ramps from 0 to 1 over this time; 0 = at once
    feedback_blend_s: float = field(
        default=0.02, metadata=rng(0.0, 60.0, unit="s", origin="bumpless return to the sensor; §3.5")
    )
    #: a guard is released when the best J falls below guard_release·J_max
    guard_release: float = field(
        default=0.25,
        metadata=rng(0.0, 1.0, lo_open=True, unit="1", origin="hysteresis on the guard; " + _BENCH),
    )
    # ---- the pressure test (evidence/pressure.py, docs/control.md §5) ---------------------
    flow_gain_test: bool = field(default=True, metadata=rng(unit="switch", origin="§5: the k_Q finding"))
    #: Λ above which H_Q (flow gain) is entered
    flow_gain_threshold: float = field(
        default=8.0, metadata=rng(0.0, 1e6, lo_open=True, unit="1 (log-likelihood)", origin="§5 k_Q runs")
    )
    flow_gain_window_s: float = field(
        default=0.5, metadata=rng(0.0, 60.0, lo_open=True, unit="s", origin="§5: tens of ms decide")
    )
    #: the smallest |θ_prod − 1| taken as a deviation to attribute
    flow_gain_min_deviation: float = field(
        default=0.05, metadata=rng(0.0, 1.0, lo_open=True, unit="1", origin="the 5 % band; §5")
    )
    #: the evidence the window must hold before a decision
    flow_gain_min_evidence_s: float = field(default=0.03, metadata=rng(0.0, 10.0, unit="s", origin="§5"))
    #: the increment excitation gate (fraction of the nominal M-sample increment K_c·S·M·Ts)
    flow_gain_excitation: float = field(
        default=0.1, metadata=rng(0.0, 1.0, unit="1 (·K_c·S·M·Ts)", origin="§5")
    )
    #: H_D (the sensor's) is decided only at Λ < −this: the costlier mistake is a flow loss
    #: compensated as a drift
    flow_gain_sensor_threshold: float = field(
        default=10.0,
        metadata=rng(
            0.0, 1e6, lo_open=True, unit="1 (log-likelihood)", origin="§5 asymmetric cost; §9.1 poweron-drift"
        ),
    )
    #: until the plant's own pressure gain is learned, either hypothesis' pressure gain is known
    #: only within ±this: the plant's load mass, piston area and hydraulic natural frequency off
    #: the model's move it (0: the model is exact, a commissioned plant)
    pressure_gain_uncertainty: float = field(
        default=0.2,
        metadata=rng(0.0, 0.5, unit="1 (relative)", origin="the uncertainty set: load mass ±20 % (§9.1)"),
    )
    #: the plant's velocity gain K_c may be off the model's by ± this without a fault: a
    #: deviation of the product within it that the pressure test leaves undecided for
    #: ``undecided_evidence`` is the plant's own flow gain, the nominal of both hypotheses from
    #: then on (0: the model is exact, a commissioned plant)
    velocity_gain_uncertainty: float = field(
        default=0.3,
        metadata=rng(0.0, 0.9, unit="1 (relative)", origin="the uncertainty set: flow gain, ω_h ±20 %"),
    )
    #: the plant has shown the model's flow gain once the averaged product stayed within
    #: ``flow_gain_min_deviation`` of 1 for this long of excited increments in a row: a later
    #: deviation is a change (a fault), never the plant's own flow gain
    plant_seen_s: float = field(
        default=0.05,
        metadata=rng(
            0.0, 10.0, unit="s (excited increments)", origin="§9.1: a drift 0.36 s after a recovery, realtime"
        ),
    )
    #: H_Q's pressure gain is known within ± this many mean steps of θ_pos between excited
    #: increments (the product's wander under position noise; a clean product keeps it exact)
    product_spread: float = field(
        default=3.0,
        metadata=rng(0.0, 100.0, unit="1 (· mean step)", origin="≈ √M; model-error draws: harm 4.5 → 2.9 %"),
    )
    #: a window that held this many times ``flow_gain_min_evidence_s`` without deciding is
    #: ambiguous about its deviation: when the product moves off it, the window starts afresh
    undecided_evidence: float = field(
        default=4.0,
        metadata=rng(1.0, 1e3, unit="1 (· min evidence)", origin="§9.1: mm-kq085-kq07, poweron-drift"),
    )
    #: no flow-gain evidence for this long after samples stepped without their data
    flow_hold_s: float = field(
        default=0.02, metadata=rng(0.0, 10.0, unit="s", origin="≈ 6 time constants of the −284 1/s pole")
    )
    #: no spool or flow-gain evidence for this long after the spool was at its stop
    spool_stop_hold_s: float = field(
        default=0.005, metadata=rng(0.0, 10.0, unit="s", origin="≈ 8 valve-pole time constants (0.6 ms)")
    )
    #: the spool model in use must have stood this long before a sample teaches the baseline
    baseline_settle_s: float = field(default=0.1, metadata=rng(0.0, 60.0, unit="s", origin="§9.1 baseline"))
    #: the healthy pressure baseline forgets with this time constant (s of healthy samples)
    baseline_window_s: float = field(
        default=2.0, metadata=rng(0.0, 1e3, lo_open=True, unit="s", origin="§9.1 baseline")
    )
    #: … and is used once it holds this much healthy operation
    baseline_min_s: float = field(default=0.2, metadata=rng(0.0, 1e3, unit="s", origin="§9.1 baseline"))
    #: … within these bounds: ω_h, mass or flow gain off the model by up to a factor 2
    baseline_limits: tuple[float, ...] = field(
        default=(0.5, 2.0),
        metadata=rng(0.0, 1e3, length=(2, 2), unit="1", origin="plant off by 2× either way"),
    )
    #: … and only where it differs from 1 by more than this
    baseline_deadband: float = field(
        default=0.05, metadata=rng(0.0, 1.0, unit="1", origin="0.2 bar pressure resolution: 2–3 % LS error")
    )
    # ---- the increment product θ_prod (evidence/increments.py) ----------------------------
    #: the regression window M (samples; also mmac-paper's and smac's increment regression)
    increment_window: int = field(default=10, metadata=rng(1, 1000, unit="samples", origin="§4"))
    #: an increment excites θ_prod only where the spool's motion is this many times the noise
    excitation_snr: float = field(
        default=2.0, metadata=rng(0.0, 1e3, unit="1 (·σ of one sample)", origin="20 µm noise runs; §9.1")
    )
    #: the reading's one-sample noise is averaged with this weight (≈ 1/weight samples)
    noise_weight: float = field(
        default=0.01, metadata=rng(0.0, 1.0, lo_open=True, unit="1/samples", origin="100-sample average")
    )
    #: a reading that moved over an increment within this long is a moving sensor
    moving_s: float = field(default=0.1, metadata=rng(0.0, 60.0, unit="s", origin="§3.5 guarded gain"))
    # ---- the creep (evidence/creep.py) ----------------------------------------------------
    #: an increment is near null when the spool moves the piston by less than this share of full flow
    creep_null_share: float = field(
        default=0.02,
        metadata=rng(0.0, 1.0, unit="1 (·K_c·x_v,max)", origin="docs/physics.md nonlinear plant"),
    )
    creep_samples: int = field(
        default=200,
        metadata=rng(1, 100000, unit="increments", origin="docs/control.md §9.1: the creep's mean"),
    )
    creep_min_samples: int = field(
        default=50,
        metadata=rng(1, 100000, unit="increments", origin="docs/control.md §9.1: the creep's mean"),
    )
    creep_outlier_sigmas: float = field(
        default=6.0, metadata=rng(0.0, 1e3, unit="σ", origin="a jump of the reading is no creep")
    )
    #: a creep above this share of full flow is modelled (kept until below half of it)
    creep_min_share: float = field(
        default=0.03,
        metadata=rng(
            0.0, 1.0, unit="1 (·K_c·x_v,max)", origin="a linear plant's far below; single-rod 5 of 33 mm/s"
        ),
    )
    #: the joint fit Δy = θ·φ + c·τ judges the creep once its standard error is below this
    #: share of the smallest creep modelled (``creep_min_share``)
    creep_joint_se: float = field(
        default=0.25,
        metadata=rng(0.0, 10.0, unit="1 (·creep_min_share)", origin="docs/control.md §9.1: the joint fit"),
    )
    #: the joint fit judges nothing and rejects no outlier before this many increments
    creep_joint_min: int = field(
        default=10,
        metadata=rng(
            3, 100000, unit="increments (of M samples)", origin="docs/control.md §9.1: the joint fit"
        ),
    )
    #: the joint fit is a start-up measure: it closes after this many increments unjudged
    creep_joint_max: int = field(
        default=40,
        metadata=rng(
            3, 100000, unit="increments (of M samples)", origin="docs/control.md §9.1: the joint fit"
        ),
    )
    # ---- the jump test (evidence/jump.py) and the attribution ----------------------------
    jump_sigmas: float = field(
        default=6.0,
        metadata=rng(
            0.0, 1e3, lo_open=True, unit="σ̂", origin="docs/control.md §5.1: far outside Gaussian noise"
        ),
    )
    jump_noise_samples: int = field(
        default=100,
        metadata=rng(1, 100000, unit="samples", origin="docs/control.md §5.1: the increment noise σ̂"),
    )
    jump_ratio_sigmas: float = field(
        default=20.0, metadata=rng(0.0, 1e3, unit="σ̂", origin="ratio error σ̂/|y| ≤ 1/20")
    )
    jump_min_samples: int = field(
        default=10,
        metadata=rng(1, 100000, unit="samples", origin="docs/control.md §5.1: σ̂ before any judgement"),
    )
    #: after a jump, a position-model change within this long that the jump explains is the sensor's
    jump_hold_s: float = field(
        default=0.03, metadata=rng(0.0, 10.0, unit="s", origin="FRA convergence; §5.1")
    )
    #: … a model that moved by more than this from the gain in use before the jump
    jump_min_change: float = field(
        default=0.01, metadata=rng(0.0, 1.0, unit="1", origin="below the pressure test's band; §5.1")
    )
    #: a jump's attribution is verified (or withdrawn) once the increments' gain since the jump
    #: lies this many standard errors off the midpoint of the gain before and after it
    verify_significance: float = field(
        default=3.0,
        metadata=rng(0.0, 100.0, unit="1 (· standard error)", origin="§5.1: biases under 5–10 µm of noise"),
    )
    #: a model change at rest is the sensor's only once the reading moved this many σ̂ (its
    #: one-sample noise) beyond the model's travel since the motion stopped, ``increment_window``
    #: samples in a row
    rest_reading_snr: float = field(
        default=3.0,
        metadata=rng(0.0, 1e3, unit="σ̂", origin="§5.1: campaign draws under 17–19 µm of noise"),
    )
    #: a re-base of x̂ larger than this many reference amplitudes at once is no sensor gain change
    rebase_limit: float = field(
        default=2.0,
        metadata=rng(0.0, 1e3, lo_open=True, unit="reference amplitudes", origin="campaign run 1453"),
    )
    # ---- the still sensor (evidence/still.py) ---------------------------------------------
    still_min_travel_m: float = field(
        default=3e-4, metadata=rng(0.0, 1.0, lo_open=True, unit="m", origin="≈ 9 ms at K_c·x_v,max 33 mm/s")
    )
    still_fraction: float = field(
        default=0.05,
        metadata=rng(0.0, 1.0, unit="1", origin="15 µm of 0.3 mm: above noise, below live gains"),
    )
    # ---- the sensor's return, the monitor, the fallback -----------------------------------
    #: a held-off sensor returns when, read through θ̂_D, it is this close to x̂ (·reference amplitude)
    sensor_return_gap: float = field(
        default=0.5, metadata=rng(0.0, 1e3, lo_open=True, unit="reference amplitudes", origin="§3.5")
    )
    #: … or when θ_prod is this many times ``sensor_failed_below``: the sensor follows the spool
    follows_factor: float = field(
        default=2.0,
        metadata=rng(0.0, 1e3, unit="1", origin="θ_prod ≥ 0.3 with sensor_failed_below 0.15; §3.5"),
    )
    #: a rule must fire this long in a row to fall back; the fallback ends after this long quiet
    monitor_confirm_s: float = field(default=0.003, metadata=rng(0.0, 1.0, unit="s", origin="§7 monitor"))
    monitor_reengage_s: float = field(default=0.05, metadata=rng(0.0, 10.0, unit="s", origin="§7 monitor"))
    #: a sensor whose increments follow the spool with at least this gain is not failed
    monitor_sensor_alive: float = field(default=0.5, metadata=rng(0.0, 2.5, unit="1", origin="§7 monitor"))
    #: an adaptive estimate within this of its clip counts as at its limit
    at_limit_margin: float = field(
        default=0.01, metadata=rng(0.0, 1.0, unit="1", origin="§7 ESTIMATE_AT_LIMIT")
    )
    #: entering or leaving the nominal fallback moves the divisors over this time
    fallback_ramp_s: float = field(
        default=0.02, metadata=rng(0.0, 10.0, unit="s", origin="§7 bumpless fallback")
    )
    # ---- the actuator and the sample clock -------------------------------------------------
    #: a spool sample is at the stop when the LVDT reads within this fraction of the stroke
    spool_stop_fraction: float = field(
        default=0.98,
        metadata=rng(
            0.0,
            1.0,
            lo_open=True,
            unit="1 (·stroke)",
            origin="docs/control.md §7: the spool held at its stop",
        ),
    )
    # ---- the spool overlap (evidence/overlap.py) -----------------------------------------
    #: the uncertainty set's widest spool overlap, each side of null (m of spool): inside it a
    #: critically lapped valve passes flow and an overlapped one none
    spool_overlap_max_m: float = field(
        default=2e-4,
        metadata=rng(0.0, 0.01, unit="m", origin="the uncertainty set: overlap ≤ 2 % of the stroke"),
    )
    #: an in-band stretch is evidence once x̂ travelled this many times the reading's noise in it
    overlap_evidence_snr: float = field(
        default=5.0,
        metadata=rng(0.0, 1e3, lo_open=True, unit="1 (·σ̂)", origin="docs/control.md §9.1 overlap"),
    )
    #: … and the overlap is shown once the share, this many standard errors either side of
    #: it, lies within ±``overlap_shown_below`` of 0 …
    overlap_confidence: float = field(
        default=3.0,
        metadata=rng(0.0, 100.0, unit="1 (standard errors)", origin="3 standard errors: 0.27 % two-sided"),
    )
    #: … after at least this many stretches …
    overlap_min_stretches: int = field(
        default=3, metadata=rng(1, 10**6, unit="stretches", origin="docs/control.md §9.1 overlap")
    )
    #: … the share of x̂'s in-band travel the piston made: an overlapped valve's is 0, a
    #: critically lapped one's 1
    overlap_shown_below: float = field(
        default=0.5, metadata=rng(0.0, 1.0, unit="1", origin="halfway between overlapped (0) and lapped (1)")
    )
    #: the actuator is current-saturated when the echo falls short of the command by more than this
    echo_short_a: float = field(
        default=3e-5, metadata=rng(0.0, 1.0, unit="A", origin="DBC: 0.2 µA echo and 10 µA setpoint steps")
    )
    #: kept commands are taken as applied when the span's last echo matches within this
    wire_match_a: float = field(
        default=3e-5, metadata=rng(0.0, 1.0, unit="A", origin="DBC: 10 µA setpoint + 1.5 µA echo roundings")
    )
    #: the sensor may move x̂ across a redone span within this multiple of the LVDT's bound
    bridge_margin: float = field(default=1.25, metadata=rng(1.0, 1e3, unit="1", origin="§3.3 bridged spans"))


def gate_table(tuning: ControlTuning | None = None) -> list[str]:
    """The rows of docs/control.md's gate table: name, default, unit, origin (markdown)."""
    t = tuning if tuning is not None else ControlTuning()
    rows = ["| gate | default | unit | origin |", "|---|---|---|---|"]
    for f in dataclasses.fields(t):
        meta: dict[str, Any] = dict(f.metadata)
        value = getattr(t, f.name)
        if isinstance(value, tuple):
            shown = ", ".join(f"{v:g}" for v in value)
        elif isinstance(value, bool):
            shown = str(value).lower()
        else:
            shown = f"{value:g}"
        rows.append(f"| `{f.name}` | {shown} | {meta.get('unit', '')} | {meta.get('origin', '')} |")
    return rows
