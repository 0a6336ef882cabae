"""The evidence layer: every piece of evidence behind one object, run in one fixed order.

The banks say how far the position channel's gain k_DFT·k_Q (as the level models read it) and
the spool channel's k_LOE are off; they cannot say *whose* a position-channel change is, nor
whether compensating is better than not. :class:`EvidenceLayer` answers that once per fresh
sample, after both banks (:meth:`EvidenceLayer.update`), in this order — each piece reads what
the ones before it concluded on the same sample:

1. **increments** (:class:`.Increments`): θ_prod, the offset-free product, with its noise,
   freshness, settling and the still-sample count; the **creep** learns from its near-null
   increments (a change of the creep in use restarts the position channel: what it concluded
   was reached on increments the creep was read into);
2. **overlap** (:class:`.SpoolOverlap`): whether the plant has shown a spool overlap; once it
   has, x̂ integrates the in-band spool at the share the piston made of it and the position
   channel restarts (what it concluded was reached on a model without the overlap);
3. **pressure test** (:class:`.PressureTest`): the healthy baseline, the likelihood ratio and the
   H_D / H_Q decision; entering or leaving H_Q is applied to the estimates at once
   (:meth:`.Estimates.enter_flow` / :meth:`~.Estimates.leave_flow`);
4. **do-no-harm monitor** (:class:`.HarmMonitor`): the estimates in use against θ_prod and
   their clips → the nominal fallback;
5. **jump attribution** (:class:`.SensorAttribution` with :class:`.LevelJump`): whether the
   position model in use may be compensated as the sensor's.

The **still sensor** (:class:`.StillSensor`) is the one piece that runs before the position
bank (:meth:`EvidenceLayer.stop_phase`): a sensor found dead moves x̂, and the position bank
must regress on that x̂ on the same sample.

Each piece is held behind its protocol (:mod:`.protocols`): replacing one is a change in one
place.

Its input is the fresh sample (the :class:`~ehpss_hil.control.base.Measurement`) and the loop's
state around it; the result is one :class:`Attribution` record (one object, rewritten on each
update: read it before the next). The loop asks the layer, while it closes, for the gain to
read a guarded sensor through (:meth:`~EvidenceLayer.guarded_gain`) and whether the sensor is
live, dead or follows the spool: questions on the same state.
"""

from __future__ import annotations

import math
from enum import IntEnum

from ...physics.params import PlantParams
from ..bank import ScalarBank
from ..base import Measurement
from ..estimates import Estimates
from ..sampleclock import SampleClock
from ..supervisor import Supervisor
from ..tuning import ControlTuning
from .attribution import SensorAttribution
from .increments import Increments
from .monitor import FallbackReason, HarmMonitor
from .overlap import SpoolOverlap
from .pressure import PressureTest
from .protocols import (
    HarmEvidence,
    IncrementEvidence,
    JumpEvidence,
    OverlapEvidence,
    PressureEvidence,
    StillEvidence,
)
from .still import StillSensor


class Hypothesis(IntEnum):
    """Whose the present deviation of the position channel is taken to be."""

    NONE = 0  #: nothing attributed: the raw sensor is fed back (the estimates kept)
    SENSOR = 1  #: the sensor's (H_D decided, or a jump explains the model): compensate it
    FLOW = 2  #: the flow gain's (H_Q): k̂_Q = θ_prod, the sensor healthy


class Attribution:
    """What the evidence concluded on one sample (rewritten by every update)."""

    __slots__ = ("fallback", "hypothesis", "k_q", "position_nominal", "ramp_samples", "reason", "restarted")

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Nothing concluded yet."""
        self.hypothesis = Hypothesis.NONE
        #: the flow gain in use (θ_prod under H_Q, else 1)
        self.k_q = 1.0
        #: feed the raw sensor back (θ̂_D = 1 in the loop), over ``ramp_samples`` samples
        self.position_nominal = False
        self.ramp_samples = 1
        #: the do-no-harm monitor holds the loop on nominal compensation, and why
        self.fallback = False
        self.reason = FallbackReason.NONE
        #: the position channel was restarted on this sample (a creep came into use or left)
        self.restarted = False


class EvidenceLayer:
    """The pieces of evidence of one mmac controller, composed (see the module)."""

    # one slot per attribute: read on every fresh sample (an instance dict of more than 30 keys
    # is not shared, and its reads take the interpreter's slower path)
    __slots__ = (
        "_alive",
        "_baseline_settle",
        "_creep_on",
        "_dead_evidence",
        "_failed_below",
        "_flow_hold",
        "_flow_spool_model",
        "_follows",
        "_hyp",
        "_in_flow",
        "_lim_d_hi",
        "_lim_l_lo",
        "_moving_samples",
        "_on",
        "_ramp_n",
        "_spool_age",
        "_spool_age_model",
        "_stop_hold",
        "attribution",
        "clock",
        "dead",
        "est",
        "inc",
        "monitor",
        "overlap",
        "pos_bank",
        "pos_sup",
        "pressure",
        "record",
        "spool_bank",
        "spool_sup",
        "still",
    )

    def __init__(
        self,
        plant: PlantParams,
        ts_s: float,
        scale_spool_m: float,
        tuning: ControlTuning,
        estimates: Estimates,
        spool: tuple[ScalarBank, Supervisor],
        position: tuple[ScalarBank, Supervisor],
        clock: SampleClock,
    ) -> None:
        """``scale_spool_m``: the nominal spool amplitude S (m); ``estimates``: the estimator
        state the decisions are applied to; ``spool``, ``position``: the channels' bank and
        supervisor (read; the position channel is restarted or re-seeded by the evidence);
        ``clock``: the sample clock (the current echo, the samples a sample stands for; it
        steps :attr:`pressure`'s model when the flow-gain test is on)."""
        t = tuning
        self.est = estimates
        self.clock = clock
        self.spool_bank, self.spool_sup = spool
        self.pos_bank, self.pos_sup = position
        self.inc: IncrementEvidence = Increments(plant, ts_s, scale_spool_m, t)
        self.pressure: PressureEvidence = PressureTest(plant, ts_s, t)
        self.still: StillEvidence = StillSensor(plant.velocity_gain_1_s, ts_s, t)
        self.overlap: OverlapEvidence = SpoolOverlap(plant.velocity_gain_1_s, ts_s, t)
        self.attribution: JumpEvidence = SensorAttribution(
            self.inc, self.pressure, ts_s, t.sensor_failed_below, t
        )
        self.monitor: HarmEvidence = HarmMonitor(
            t.flow_gain_min_deviation,
            t.increment_window,
            round(t.monitor_confirm_s / ts_s),
            round(t.monitor_reengage_s / ts_s),
            t.sensor_failed_below,
            t.monitor_sensor_alive,
        )
        self.record = Attribution()
        self._hyp = (Hypothesis.NONE, Hypothesis.SENSOR, Hypothesis.FLOW)  # looked up once
        self._on = t.flow_gain_test
        self._failed_below = t.sensor_failed_below
        self._alive = t.monitor_sensor_alive
        self._follows = t.follows_factor
        self._lim_d_hi = t.k_dft_limits[1] - t.at_limit_margin
        self._lim_l_lo = t.k_loe_limits[0] + t.at_limit_margin
        self._flow_hold = max(1, round(t.flow_hold_s / ts_s))
        self._stop_hold = max(1, round(t.spool_stop_hold_s / ts_s))
        self._baseline_settle = max(1, round(t.baseline_settle_s / ts_s))
        self._moving_samples = max(1, round(t.moving_s / ts_s))
        self._ramp_n = max(1, round(t.fallback_ramp_s / ts_s))

    def reset(self) -> None:
        """Nothing seen, nothing attributed (after the banks and supervisors were reset)."""
        self.inc.reset()
        self.pressure.reset()
        self.monitor.reset()
        self.still.reset()
        self.overlap.reset()  # an overlap shown is the plant's: x̂ (reset by the loop) keeps it
        self.est.set_band_gain(self.overlap.gain)
        self.attribution.reset()
        self.record.clear()
        self.dead = False  # the sensor stood still through a stop phase (still.py)
        self._dead_evidence = 0  # excited increments of θ_prod taken since it was found dead
        self._in_flow = False
        self._flow_spool_model = self.spool_sup.active
        self._spool_age = 0  # samples the spool model in use has been in use
        self._creep_on = False  # a creep is in use (x̂ integrates it)
        self._spool_age_model = self.spool_sup.active

    # ---- before the position bank ----------------------------------------------------------
    def gap(self) -> None:
        """Samples were stepped without their data: no pressure evidence for ``flow_hold_s``."""
        if self._on:
            self.pressure.hold_off(self._flow_hold)

    def spool_stop(self) -> None:
        """The spool was at its stop: no pressure evidence for ``spool_stop_hold_s``."""
        self.pressure.hold_off(self._stop_hold)

    def stop_phase(self, at_stop: bool, spool_m: float, position_m: float, x_hat_m: float) -> bool:
        """The still sensor on this sample; True when the sensor was found dead now (x̂ is then
        placed where the spool took the piston, and the loop holds the sensor off)."""
        x_dead = self.still.update(at_stop, spool_m, position_m, x_hat_m)
        if x_dead is None:
            return False
        k_q = self.est.k_q
        if self.pressure.flow_fault:
            # a flow gain attributed before (H_Q: x̂ is in x/k̂_Q units) is the plant's: x̂ goes
            # on at it and the compensation keeps it; the hypothesis itself ends (no sensor)
            k_q = self.est.k_q
            self.pressure.forget_attribution()
            self._in_flow = False
        self.dead = True
        self._dead_evidence = 0
        self.est.place_dead(position_m, x_dead, k_q)
        return True

    # ---- after both banks ------------------------------------------------------------------
    def update(
        self, meas: Measurement, k_loe: float, excited: bool, warm: bool, broken: bool, trusted: bool
    ) -> Attribution:
        """One fresh sample after both banks: the pieces in the module's order; the record.
        ``k_loe``: the spool channel's k̂_LOE in use; ``excited``: the spool not at or just off
        its stop; ``warm``: the loop still in its warm-up; ``broken``: samples were missed and
        not redone; ``trusted``: the loop fed the sensor back at the last fresh sample. The
        current echo and the samples this one stands for come from the sample clock.

        This runs on every fresh sample: the layer's own steps around the pieces (the creep in
        use, the inputs of the monitor) are written out here, one call per piece."""
        rec = self.record
        rec.restarted = False
        est, pt, inc = self.est, self.pressure, self.inc
        ss, ps = self.spool_sup, self.pos_sup
        position_m = meas.position_m
        # 1. increments: θ_prod, and the creep on this sample (x̂ moves with it, in x/k̂_Q units)
        prod = inc.product(position_m, meas.spool_m, self.clock.span, excited)
        if self.dead and inc.product_updated:
            self._dead_evidence += 1
        spool_model = ss.active
        if spool_model != self._flow_spool_model:
            # the pressure prediction scales with k̂_LOE: evidence taken with another k̂_LOE
            # favours the wrong hypothesis
            self._flow_spool_model = spool_model
            pt.restart()
            pt.hold_off(self._flow_hold)
        rate = inc.creep.rate_m_s
        creep = rate / prod if prod >= self._failed_below else 0.0
        if creep != est.xhat.creep_m_s:  # unchanged on most samples: no call
            est.set_creep(creep)
        if (rate != 0.0) != self._creep_on:
            self._creep_on = not self._creep_on
            self._restart_position(position_m)
        # 2. the overlap: once the plant has shown one, x̂ integrates the band at its gain and
        # the position channel starts over (what it concluded was reached without it)
        shows = (
            trusted
            and not ps.guarded
            and ps.active == ps.initial
            and not pt.flow_fault
            and not self.dead
            and self.clock.span == 1
        )
        if self.overlap.update(meas.spool_m, position_m, shows, est.theta_d, inc.reading_noise_m):
            est.set_band_gain(self.overlap.gain)
            self._restart_position(position_m)
        age = self._spool_age = self._spool_age + 1 if spool_model == self._spool_age_model else 0
        self._spool_age_model = spool_model
        # 3. the pressure test, and H_Q entered or left in the estimates
        fresh = inc.product_fresh
        healthy = not warm and not ss.guarded and not ps.guarded and age >= self._baseline_settle
        theta_l = self._pressure_theta_l(k_loe, warm) if warm or ss.guarded else k_loe
        pt.update(
            self.clock.echo,
            meas.load_pressure_pa,
            theta_l,
            prod,
            est.theta_d,
            healthy,
            fresh,
            inc.product_updated,
        )
        if pt.flow_fault:
            # under position noise the averaged product (compensated_product): a current
            # divided by one noisy θ_pos carries the noise into the loop
            est.enter_flow(position_m, pt.compensated_product(prod), k_loe, pt.sensor_gain)
            self._in_flow = True
        elif self._in_flow:  # back to H_D: the product is the sensor's gain (≈ 1 when it vanished)
            self._in_flow = False
            est.leave_flow(position_m, prod)
            self.pos_bank.seed_ria(prod)
            ps.force(self.pos_bank.ria)
            est.set_sensor_gain(self.pos_bank.theta[self.pos_bank.ria], pt.k_base)
        # 4. the do-no-harm monitor: the position check only where the sensor is read through
        # θ̂_D; under the guard (position_guarded()) the loop runs on x̂ (no model explains the
        # sensor; θ_prod, fitted on the same sensor, neither)
        guarded = ps.guarded and not pt.flow_fault
        at_limit = (ps.active >= self.pos_bank.n_fixed and not guarded and est.theta_d >= self._lim_d_hi) or (
            spool_model >= self.spool_bank.n_fixed and not ss.guarded and k_loe <= self._lim_l_lo
        )
        mon = self.monitor
        rec.fallback = mon.update(est.k_dft * est.k_q, inc.theta_prod, fresh and not guarded, at_limit)
        rec.reason = mon.reason
        # 5. the jump attribution
        att = self.attribution
        sensor = att.update(position_m, est.theta_d, ps.active, ps.guarded, broken, trusted)
        flow = pt.flow_fault
        rec.position_nominal = not (sensor or flow)
        rec.ramp_samples = 1 if att.by_jump else self._ramp_n
        rec.hypothesis = self._hyp[2 if flow else (1 if sensor else 0)]
        rec.k_q = est.k_q
        return rec

    def _restart_position(self, position_m: float) -> None:
        """The plant model changed (a creep came into use or left it): what the position channel
        concluded under the old model — its models, the guard, the attribution, a flow-gain
        hypothesis — was reached on increments the creep was read into. Start it over from the
        sensor as it reads now (x̂ = y_s, nominal), the spool channel and the creep kept."""
        ps = self.pos_sup
        switches = ps.switches
        self.pos_bank.reset()
        ps.reset()
        ps.switches = switches
        self.attribution.reset()
        self.pressure.forget_attribution()
        self.monitor.reset()
        self.est.restart(position_m)
        self._in_flow = False
        self.record.restarted = True

    def _pressure_theta_l(self, k_loe: float, warm: bool) -> float:
        """k̂_LOE for the pressure test: the spool model in use, or while the spool channel is
        still in its warm-up the best-scoring one (a power-on LOE is not switched to yet)."""
        if warm or self.spool_sup.guarded:
            j = self.spool_bank.j
            return self.spool_bank.theta[j.index(min(j))]
        return k_loe

    # ---- questions the loop asks while it closes -------------------------------------------
    def position_guarded(self) -> bool:
        """The position guard is up and the deviation is not the flow gain's."""
        return self.pos_sup.guarded and not self.pressure.flow_fault

    def jumped_under_guard(self) -> bool:
        """The reading jumped since the position guard rose."""
        return self.attribution.jumped_since_guard

    def guarded_gain(self) -> float | None:
        """Under the guard, the gain to read a live sensor through (None: x̂ carries the loop).
        x̂ integrates the spool at the model's flow gain, so on a plant off the model it is the
        one that is off. Before the creep is known, a moving sensor that gave no sign of a fault
        (a jump, standing still) is read raw (1). Once its increments have followed the spool
        for a full window (M excited increments) since the guard rose, at a live gain and
        settled, and it is not dead, it is read through the gain the evidence gives it: the
        gain its last jump went to, else θ_prod when H_D was decided, else 1 (raw)."""
        if not self._on:  # no increment evidence kept (the flow-gain test is off)
            return None
        inc, att = self.inc, self.attribution
        if (
            not (self.dead or inc.creep.judged or att.jumped_since_guard)
            and inc.still_samples < self._moving_samples
        ):
            return 1.0
        if self.dead or not (inc.product_fresh and inc.product_settled and inc.theta_prod >= self._alive):
            return None
        if att.since_guard < inc.increment_window:
            return None
        kb = self.pressure.k_base  # the gains below are the product's: k_DFT times the plant's
        if math.isfinite(att.jump_gain) and att.jump_gain >= self._alive:
            return att.jump_gain / kb
        return inc.theta_prod / kb if self.pressure.sensor_favoured else 1.0

    def sensor_live(self) -> bool:
        """The sensor follows the spool, so it may be fed back raw. Under the guard with no jump
        since it rose (x̂ is the suspect): θ_prod, fresh or not, at ``follows_factor`` times the
        failed-sensor threshold or more. Otherwise θ_prod fresh, at a live gain and settled, and
        after a jump a full window of increments since the guard rose. Never while dead."""
        inc = self.inc
        if self.dead:
            return False
        guarded = self.pos_sup.guarded
        att = self.attribution
        if guarded and not att.jumped_since_guard:
            return inc.theta_prod >= self._follows * self._failed_below
        if not (inc.product_fresh and inc.theta_prod >= self._alive):
            return False
        if guarded and att.since_guard < inc.increment_window:
            return False
        return inc.product_settled

    def sensor_dead(self) -> bool:
        """Found standing still through a full-flow stop phase and not seen following the spool
        since (a full window of excited increments after the finding, at a live gain)."""
        if self.dead and self._dead_evidence >= self.inc.increment_window and self.sensor_follows_spool():
            self.dead = False
            self.est.revive()
        return self.dead

    def sensor_follows_spool(self) -> bool:
        """θ_prod (fresh) says the sensor moves with the spool integral, at ``follows_factor``
        times the failed-sensor threshold or more."""
        inc = self.inc
        return inc.product_fresh and inc.theta_prod >= self._follows * self._failed_below
