"""The five controller modes and the factory :func:`make_controller`.

Modes (docs/design.md §5): ``nrc`` (eq 39 PI only), ``oracle`` (compensation with the true faults, for
benchmarks only), ``smac`` (one joint adaptive model), ``mmac-paper`` (the paper's joint bank),
``mmac`` (per-channel banks on the spool LVDT and the position sensor).

Model slots (DBC CTRL_INDEX ``ModelSlot`` 0–15, reported in :class:`ControllerStatus`):

=====  ==========================================  =====  ===================================
slot   model                                       slot   model
=====  ==========================================  =====  ===================================
0      spool: fixed k_LOE = 1.0                    8      position: RIA
1      spool: fixed k_LOE = 0.5                    9      joint (mmac-paper): nominal (1, 1)
2      spool: FRA                                  10     joint: LOE 50 % (0.5, 1)
3      spool: RIA                                  11     joint: drift 0.5 (1, 0.5)
4      position: fixed k_DFT = 1                   12     joint: FRA
5      position: fixed k_DFT = 0.5                 13     joint: RIA
6      position: fixed k_DFT = 0 (failed sensor)   14     smac: the single adaptive model
7      position: FRA                               15     (unused)
=====  ==========================================  =====  ===================================

Slots 0–8 assume the default fixed values of :class:`ControlTuning`; other fixed tuples shift
the FRA/RIA slots (``SPOOL_SLOT0 + len(fixed_k_loe)`` …). ``-1`` means "no bank" (nrc, oracle).
"""

from __future__ import annotations

import math

from ..errors import ModelError
from ..physics.faults import FaultState
from ..physics.params import Params
from .base import Controller, Measurement, NominalMotion, PaperMotion, ValveCommand
from .compensation import compensated_current, sensor_trusted
from .pi import PiLaw
from .predictors import ModelPosition, ValvePredictor
from .tuning import ControlTuning

SPOOL_SLOT0 = 0
POSITION_SLOT0 = 4
JOINT_SLOT0 = 9
SMAC_SLOT = 14


class LoopBase(Controller):
    """Shared parts of the project's modes: PI, valve predictor, model position, command
    object, probes. A mode implements :meth:`step` (and may extend :meth:`_build`,
    :meth:`_reset_mode` and the probes)."""

    mode = "base"
    #: during the warm-up x̂ is set to the sensor every sample (modes without a position model);
    #: ``mmac`` seeds x̂ once and identifies the sensor gain from the start instead
    warmup_tracks_sensor = True

    # every attribute a slot: the cycle reads them all the time, and an instance dict of more
    # than 30 keys is not shared (its reads take the interpreter's slower path). A mode adds
    # its own in its __slots__; anything else (the ABC has none) lands in the instance dict.
    __slots__ = (
        "_applied_dft",
        "_applied_loe",
        "_blend",
        "_blend_from",
        "_blend_step",
        "_cmd",
        "_echo",
        "_echo_short_a",
        "_failed_below",
        "_held_offset",
        "_offset_kept",
        "_offset_share",
        "_ramp_d",
        "_ramp_l",
        "_ramp_n",
        "_return_gap_m",
        "_sent",
        "_sent_prev",
        "_stop_level_m",
        "_trusted_offset",
        "_warm_left",
        "_warm_samples",
        "_y_s",
        "k_dft_hat",
        "k_f",
        "k_loe_hat",
        "k_q_hat",
        "min_theta_l",
        "nominal",
        "params",
        "pi",
        "position_nominal",
        "reference",
        "scale_pos_m",
        "scale_spool_m",
        "sensor_held_off",
        "sensor_trusted",
        "stroke_m",
        "ts_s",
        "tuning",
        "valve",
        "xhat",
    )

    def __init__(self, tuning: ControlTuning, reference: NominalMotion | None) -> None:
        self.tuning = tuning
        self.reference: NominalMotion = reference if reference is not None else PaperMotion()
        self.k_loe_hat = 1.0
        self.k_dft_hat = 1.0
        self.k_q_hat = 1.0
        self.sensor_trusted = True

    # ---- configuration ---------------------------------------------------------------------
    def configure(self, params: Params, ts_s: float) -> None:
        """Build everything (ZOH maps, gains, banks) for sample time ``ts_s`` (s)."""
        if not ts_s > 0.0:
            raise ModelError(f"sample time must be positive, got {ts_s}")
        self.params = params
        self.ts_s = ts_s
        self.k_f = params.controller.k_f
        self.pi = PiLaw(params.controller, ts_s)
        self.valve = ValvePredictor(params.plant, ts_s)
        self.min_theta_l = self.tuning.k_loe_limits[0]
        self.stroke_m = params.plant.spool_stroke_m
        self.valve.stop_m = self.stroke_m
        self._stop_level_m = self.tuning.spool_stop_fraction * self.stroke_m
        self._echo_short_a = self.tuning.echo_short_a
        self.xhat = ModelPosition(
            params.plant, ts_s, self.tuning.anchor_rate_1_s, self.tuning.spool_overlap_max_m
        )
        ref = self.reference
        self.scale_pos_m = ref.amplitude_m if ref.amplitude_m > 0.0 else 1e-3
        self.scale_spool_m = ref.spool_amplitude_m if ref.spool_amplitude_m > 0.0 else 1.52e-3
        self._cmd = ValveCommand()
        self._failed_below = self.tuning.sensor_failed_below
        self._return_gap_m = self.tuning.sensor_return_gap * self.scale_pos_m
        tb = self.tuning.feedback_blend_s
        self._blend_step = 1.0 if tb <= ts_s else ts_s / tb
        self._offset_share = self.tuning.velocity_gain_uncertainty
        self._blend = 1.0
        self._echo = 0.0
        self._y_s = 0.0
        self._warm_samples = round(self.tuning.warmup_s / ts_s)
        self._ramp_n = max(1, round(self.tuning.fallback_ramp_s / ts_s))
        self._build()
        self.reset()

    def _build(self) -> None:
        """Mode-specific construction (banks, supervisors)."""

    def reset(self) -> None:
        """Integrators, predictors, estimates and supervisors back to the start."""
        self.pi.reset()
        self.valve.reset()
        self.xhat.reset()
        self._echo = 0.0
        self._y_s = 0.0
        self._sent = self._sent_prev = 0.0  # the currents commanded in the last two cycles (A)
        self.k_loe_hat = 1.0
        self.k_dft_hat = 1.0
        self.k_q_hat = 1.0
        self.sensor_trusted = True
        self.sensor_held_off = False
        self.nominal = False
        self.position_nominal = False
        # per divisor (current, feedback): samples left, ramp length, value at the ramp start
        self._ramp_l = [0, 1, 1.0]
        self._ramp_d = [0, 1, 1.0]
        self._applied_loe = self._applied_dft = 1.0
        self._blend = 1.0
        self._held_offset = 0.0  # fed-back position − k̂_Q·x̂ at the last trusted sample (m)
        self._trusted_offset = 0.0  # the same at the last sample the models trusted the sensor (m)
        self._blend_from = 0.0  # the offset from x̂ the blend back to the sensor starts at (m)
        self._offset_kept = False  # x̂ has carried the loop from _trusted_offset since the reading jumped
        self._warm_left = self._warm_samples
        self._reset_mode()

    def _reset_mode(self) -> None:
        """Mode-specific reset."""

    # ---- the cycle -------------------------------------------------------------------------
    def _finish(self, meas: Measurement, feedback: float) -> ValveCommand:
        """The PI on ``feedback`` (sensor units), its current divided by the divisor in use: the
        cycle's command. The PI's anti-windup is told +1/−1 when the actuator is saturated
        upwards/downwards, judged on this sample: the spool LVDT at the stop, or a current echo
        short of the command it answers (the one sent two cycles ago: one sample of transport
        delay) by more than ``echo_short_a`` (A); a sample without data keeps the previous
        judgement."""
        pi = self.pi
        if meas.fresh:
            y_v, lvl = meas.spool_m, self._stop_level_m
            if y_v >= lvl:
                pi.saturated = 1
            elif y_v <= -lvl:
                pi.saturated = -1
            else:
                sent = self._sent_prev
                short = abs(sent) - abs(meas.coil_current_a) > self._echo_short_a
                pi.saturated = (1 if sent > 0.0 else -1) if short else 0
        i = compensated_current(pi.step(meas.reference_m, feedback), self._applied_loe, self.min_theta_l)
        cmd = self._cmd
        cmd.current_a = i
        self._sent_prev, self._sent = self._sent, (i if math.isfinite(i) else 0.0)
        return cmd

    def set_nominal(self, nominal: bool) -> None:
        """Compensate nominally (k̂ = 1: the plain PI loop on the raw sensor) or with the
        estimates; the divisors in use move between the two over ``fallback_ramp_s``."""
        if nominal != self.nominal:
            self.start_ramp(self._ramp_n)
            self.nominal = nominal

    def set_position_nominal(self, nominal: bool, samples: int) -> None:
        """Feed the raw sensor back (θ̂_D = 1 in the loop, the estimates kept) or the sensor
        through θ̂_D; the feedback divisor moves between the two over ``samples``."""
        if nominal != self.position_nominal:
            self.start_ramp(samples, current=False)
            self.position_nominal = nominal

    def start_ramp(self, samples: int, current: bool = True, feedback: bool = True) -> None:
        """Move the divisors in use (the current's and/or the feedback's) from where they are
        to their targets over ``samples``."""
        n = max(1, samples)
        if current:
            self._ramp_l = [n, n, self._applied_loe]
        if feedback:
            self._ramp_d = [n, n, self._applied_dft]

    def _apply(self) -> None:
        """The current divisor and the feedback divisor in use this cycle."""
        tl, td = (1.0, 1.0) if self.nominal else (self.k_loe_hat, self.k_dft_hat)
        if self.position_nominal:
            td = 1.0
        r = self._ramp_l
        if r[0] > 0:
            r[0] -= 1
            tl += r[0] / r[1] * (r[2] - tl)
        r = self._ramp_d
        if r[0] > 0:
            r[0] -= 1
            td += r[0] / r[1] * (r[2] - td)
        self._applied_loe, self._applied_dft = tl, td

    def _close(self, meas: Measurement) -> ValveCommand:
        """Common tail: trust decision, anchoring, feedback, PI, compensation.

        While the sensor is trusted the fed-back position is ``x̂ + o + b·(y_s/θ̂_D − x̂ − o)``
        with the blend b ramping to 1 over ``feedback_blend_s`` after a period of distrust (b = 1:
        exactly ``y_s/θ̂_D``) and o the offset the distrust ended at; untrusted: x̂ alone (o = 0),
        or, under a position guard the reading jumped in, x̂ plus the offset of the last reading
        the models trusted, if a flow gain inside the uncertainty set explains that offset
        (x̂'s own error on a plant off the model, not the reading's). This makes the switches
        to and from the sensor bumpless.
        """
        td = self.k_dft_hat
        fresh = meas.fresh
        guarded = self._position_guarded()
        self._judge_failed(meas, td, guarded)
        g: float | None = None
        model_trusted = sensor_trusted(td, self._failed_below, guarded, fresh) and not self.sensor_held_off
        if self.nominal:  # the estimates set aside, the guard (no model explains the sensor) not,
            # unless the sensor's increments follow the spool (a live sensor the level models miss)
            trusted = fresh and (not guarded or self._sensor_live())
        elif model_trusted:
            trusted = True
        else:  # the raw sensor, when the position channel compensates nominally and it is live;
            # under the guard, a live sensor read through the gain the evidence gives it
            g = self._guarded_gain() if guarded and fresh else None
            trusted = g is not None or (self.position_nominal and fresh and self._sensor_live())
        self.sensor_trusted = trusted
        self._apply()
        xh, kq = self.xhat, self.k_q_hat
        model_x = kq * xh.x  # x̂ integrates the spool without k_Q: true x ≈ k̂_Q·x̂
        warm = self._warm_left > 0
        if warm:
            self._warm_left -= 1
        if trusted:
            pos = meas.position_m
            if model_trusted:  # x̂ follows the sensor as the models read it
                ym = pos / td
                if warm and self.warmup_tracks_sensor:  # x̂ is the sensor (no model yet)
                    xh.x = ym / kq
                else:
                    xh.anchor(ym / kq)
            fd = self._applied_dft if g is None else g
            y = pos / fd if fd > 0.0 else pos
            b = self._blend
            if b < 1.0:
                b = self._blend = min(1.0, b + self._blend_step)
                base = model_x + self._blend_from
                y = base + b * (y - base)
            self._held_offset = y - model_x
            self._offset_kept = False
            if model_trusted:  # x̂'s own error, if a flow gain inside the uncertainty set explains it
                off = self._held_offset
                self._trusted_offset = off if abs(off) <= self._offset_share * abs(model_x) else 0.0
            return self._finish(meas, self.k_f * y)
        if meas.fresh:  # the sensor not trusted: x̂ itself
            self._blend = 0.0
            if guarded and self._jumped_under_guard():
                self._held_offset = self._trusted_offset
                self._offset_kept = True
            elif self._offset_kept:  # released with the sensor still out: into x̂ over the blend
                self._held_offset *= 1.0 - self._blend_step
            else:
                self._held_offset = 0.0
            self._blend_from = self._held_offset
        # a sample without data: x̂'s motion since the last fed-back position, which may stand
        # off x̂ (a raw sensor fed back while x̂ integrates at a flow gain that is not the plant's)
        return self._finish(meas, self.k_f * (model_x + self._held_offset))

    def _position_guarded(self) -> bool:
        return False

    def _judge_failed(self, meas: Measurement, theta_d: float, guarded: bool) -> None:
        """:attr:`sensor_held_off`: set while θ̂_D is below ``sensor_failed_below`` (the sensor
        declared failed), the position guard is up (no model explains it) or the sensor is
        dead (:meth:`_sensor_dead`); cleared only when
        a fresh reading through θ̂_D lands within ``sensor_return_gap`` of the model position
        k̂_Q·x̂ (m), or when :meth:`_sensor_follows_spool` (x̂ may be the one that is off). A
        stuck sensor's gain estimate, a reinitialized model adapting up from near 0, or a
        guard released over a dead sensor would otherwise hand the loop a reading far from the
        piston: fed back at once, it drives the piston away."""
        if theta_d < self._failed_below or guarded or self._sensor_dead():
            self.sensor_held_off = True
        elif self.sensor_held_off and meas.fresh:
            gap = abs(meas.position_m / theta_d - self.k_q_hat * self.xhat.x)
            self.sensor_held_off = gap > self._return_gap_m and not self._sensor_follows_spool()

    def _jumped_under_guard(self) -> bool:
        """The reading jumped since the position guard rose; never in the base loop."""
        return False

    def _guarded_gain(self) -> float | None:
        """Under the position guard: the gain to read a live sensor through instead of handing
        the loop to x̂ (None: x̂); never in the base loop."""
        return None

    def _sensor_live(self) -> bool:
        """An independent witness says the sensor is alive and follows the spool with a steady
        gain; never in the base loop."""
        return False

    def _sensor_dead(self) -> bool:
        """The sensor was found standing still through a full-flow motion and has not followed
        the spool since; never in the base loop."""
        return False

    def _sensor_follows_spool(self) -> bool:
        """An independent witness that the sensor's increments follow the spool (a live
        sensor, whatever x̂ says); none in the base loop."""
        return False

    def sensor_alive(self, theta_d: float) -> bool:
        """The sensor, read through ``theta_d``, is not failed (θ above the threshold and not
        declared failed)."""
        return theta_d >= self._failed_below and not self.sensor_held_off

    # ---- probes ----------------------------------------------------------------------------
    def probe(self) -> tuple[int, int, float, float]:
        """(active spool slot, active position slot, k̂_LOE, k̂_DFT) — cheap, every sample."""
        return (-1, -1, self.k_loe_hat, self.k_dft_hat)


class NrcController(LoopBase):
    """No reconfiguration: the eq 39 PI on the raw sensor (the stale value when a frame is lost)."""

    mode = "nrc"

    def step(self, meas: Measurement) -> ValveCommand:
        """PI on ``K_f·y_s``."""
        return self._finish(meas, self.k_f * meas.position_m)


class OracleController(LoopBase):
    """Compensation with the true fault values (benchmarks only): θ̂_L = k_LOE·k_Q, θ̂_D = k_DFT;
    a failed sensor (k_DFT < 0.15) is replaced by the model position x̂ like in ``mmac``."""

    mode = "oracle"

    def set_truth(self, faults: FaultState) -> None:
        """The true faults in force now (the simulator calls this every sample)."""
        self.k_loe_hat = faults.k_loe * faults.k_q
        self.k_q_hat = faults.k_q
        self.k_dft_hat = faults.k_dft
        self.valve.stop_m = self.stroke_m / faults.k_loe

    def step(self, meas: Measurement) -> ValveCommand:
        """Predict, integrate the (measured) spool into x̂, compensate with the truth."""
        if meas.fresh:
            self._echo = meas.coil_current_a
            self.valve.step(self._echo)
            self.xhat.integrate(meas.spool_m)
        else:
            self.xhat.integrate(faults_loe(self) * self.valve.step(self._echo))
        return self._close(meas)


def faults_loe(c: LoopBase) -> float:
    """k̂_LOE alone (the current divisor is k̂_LOE·k̂_Q): what the spool LVDT sees."""
    return c.k_loe_hat / c.k_q_hat if c.k_q_hat > 0.0 else c.k_loe_hat
