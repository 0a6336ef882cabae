"""The ``mmac`` mode: per-channel banks on the spool LVDT and the position sensor.

``mmac`` (docs/design.md §5): the spool channel ``y_v = θ_L·v`` (v: commanded spool predicted from the
current echo) and the position channel ``y_s = θ_D·x̂`` (x̂: model position from the spool LVDT),
each with fixed models + FRA + RIA, a supervisor and a guard. The spool residual depends on
k_LOE only and the position residual on k_DFT only, which is what makes them separable. The
paper's joint-model modes (``smac``, ``mmac-paper``) are in :mod:`.joint`.
"""

from __future__ import annotations

import math

from .attribution import SensorAttribution
from .bank import ScalarBank
from .base import Measurement, ValveCommand
from .controllers import POSITION_SLOT0, SPOOL_SLOT0, LoopBase
from .estimates import Estimates
from .estimator import per_sample_gain
from .flowgain import FlowGainMonitor
from .monitor import HarmMonitor
from .sampleclock import SampleClock
from .stillsensor import StillSensor
from .supervisor import Supervisor


class MmacController(LoopBase):
    """Corrected MMAC on two channels (spool, position) with bumpless compensation."""

    mode = "mmac"
    warmup_tracks_sensor = False

    def _build(self) -> None:
        t, ts = self.tuning, self.ts_s
        g = per_sample_gain(t.nlms_gain_per_ms, ts)
        lim_l = (t.k_loe_limits[0], t.k_loe_limits[1])
        lim_d = (t.k_dft_limits[0], t.k_dft_limits[1])
        self.spool_bank = ScalarBank(t.fixed_k_loe, t, ts, self.scale_spool_m, g, lim_l)
        self.pos_bank = ScalarBank(t.fixed_k_dft, t, ts, self.scale_pos_m, g, lim_d)
        self.spool_sup = Supervisor(
            self.spool_bank, t, ts, guard_epsilon=t.guard_epsilon, sustained_guard=True
        )
        self.pos_sup = Supervisor(self.pos_bank, t, ts, guard_epsilon=t.position_guard_epsilon)
        self.flow = FlowGainMonitor(self.params.plant, ts, self.scale_spool_m, t)
        self.still = StillSensor(self.params.plant.velocity_gain_1_s, ts, t)
        self.attribution = SensorAttribution(self.flow, ts, t.sensor_failed_below, t)
        self.clock = SampleClock(self.valve, self.xhat, self.flow if t.flow_gain_test else None, t)
        self.monitor = HarmMonitor(
            t.flow_gain_min_deviation,
            t.increment_window,
            round(t.monitor_confirm_s / ts),
            round(t.monitor_reengage_s / ts),
            t.sensor_failed_below,
            t.monitor_sensor_alive,
        )
        self._lim_d_hi = t.k_dft_limits[1] - t.at_limit_margin
        self._lim_l_lo = t.k_loe_limits[0] + t.at_limit_margin
        self._alive = t.monitor_sensor_alive
        self._in_flow = False
        self._flow_on = t.flow_gain_test
        self._flow_hold = max(1, round(t.flow_hold_s / ts))
        self._stop_hold = max(1, round(t.spool_stop_hold_s / ts))
        self._baseline_settle = max(1, round(t.baseline_settle_s / ts))
        self._moving_samples = max(1, round(t.moving_s / ts))
        self._follows = t.follows_factor
        self._inv_s_spool = 1.0 / self.scale_spool_m
        self._inv_s_pos = 1.0 / self.scale_pos_m
        self.est = Estimates(self.xhat, t.sensor_failed_below, t.rebase_limit * self.scale_pos_m)
        n_l, n_d = len(t.fixed_k_loe) + 2, len(t.fixed_k_dft) + 2
        self.index_slots = tuple(range(SPOOL_SLOT0, SPOOL_SLOT0 + n_l)) + tuple(
            range(POSITION_SLOT0, POSITION_SLOT0 + n_d)
        )

    def _reset_mode(self) -> None:
        self.spool_bank.reset()
        self.pos_bank.reset()
        self.spool_sup.reset()
        self.pos_sup.reset()
        self.flow.reset()
        self.monitor.reset()
        self.still.reset()
        self.attribution.reset()
        self._was_trusted = True  # the last fresh sample fed the sensor back, not on the fallback
        self._dead = False  # the sensor stood still through a stop phase (stillsensor.py)
        self._dead_evidence = 0  # excited increments of θ_prod taken since it was found dead
        self._in_flow = False
        self._flow_spool_model = self.spool_sup.active
        self.clock.reset()
        self.est.reset()
        self._spool_hold = 0  # samples left without spool evidence (the spool was at its stop)
        self._spool_age = 0  # samples the spool model in use has been in use
        self._creep_on = False  # a creep is in use (x̂ integrates it)
        self._spool_age_model = self.spool_sup.active

    def step(self, meas: Measurement) -> ValveCommand:
        """Predict, score both banks, supervise, compensate, PI."""
        est = self.est
        if meas.fresh:
            y_v = meas.spool_m
            tl_prev = est.k_loe / est.k_q
            self.valve.stop_m = self.stroke_m / max(tl_prev, self.min_theta_l)
            seeding = self.clock.seed
            gap, resync, v, xh = self.clock.sample(meas, tl_prev, self._bridge_gain())
            if seeding:
                est.seed(meas.position_m)
            if gap and self._flow_on:
                self.flow.hold_off(self._flow_hold)
            sb, ss = self.spool_bank, self.spool_sup
            lvl = self._stop_level_m
            if y_v >= lvl or y_v <= -lvl or abs(tl_prev * v) >= lvl or (gap and not resync):
                # the spool at its stop, or a gap the predictors could not redo (the valve model
                # was dead-reckoned): not evidence until the model's error has died out
                self._spool_hold = self._stop_hold
                self.flow.hold_off(self._stop_hold)
            stopped = self._spool_hold > 0
            if stopped:  # at or just off the stop: not evidence of k_LOE
                self._spool_hold -= 1
            else:
                sb.update(y_v, v)
                ss.update(abs(v) * self._inv_s_spool)
            x_dead = self.still.update(y_v >= lvl or y_v <= -lvl, y_v, meas.position_m, xh)
            if x_dead is not None and not self.flow.flow_fault:
                # the sensor stood still through a full-flow stop phase: hold it off, put x̂
                # where the spool took the piston, and regress from here (a stuck reading then
                # fits the failed-sensor model)
                self.sensor_held_off = self._dead = True
                self._dead_evidence = 0
                est.place_dead(meas.position_m, x_dead)
                xh = x_dead
            pb, ps = self.pos_bank, self.pos_sup
            if (gap and not resync) or stopped:
                # x̂ missed samples, was dead-reckoned, or integrated a spool slamming into its
                # stop (a transient no model of the valve follows exactly)
                td = est.k_dft
                if not self.pos_sup.guarded and self.sensor_alive(td) and not self.flow.flow_fault:
                    # re-anchor on the trusted sensor and start the regression over from here: a
                    # dead-reckoned offset must not be taken for a drift, nor the sensor's reading
                    # through the present θ̂_D for evidence (x̂ = y_s/θ̂_D, x0 = y0/θ̂_D)
                    est.reanchor(meas.position_m, xh)
                    self._rebase(td)
                    xh = self.xhat.x
                elif not self.flow.flow_fault:
                    pb.update(meas.position_m - est.y0, xh - est.x0)
                    ps.update(abs(xh - est.x0) * self._inv_s_pos)
            elif not self.flow.flow_fault:  # under H_Q the position channel has nothing to explain
                pb.update(meas.position_m - est.y0, xh - est.x0)
                ps.update(abs(xh - est.x0) * self._inv_s_pos)
            tl = 1.0 if ss.guarded else sb.theta[ss.active]
            est.set_channels(tl, pb.theta[ps.active])
            self._rebase(est.k_dft)
            if self._flow_on:
                self._flow_split(meas, y_v, tl)
                self._watch(tl)
                broken = gap and not resync
                sensor = self.attribution.update(
                    meas.position_m, est.k_dft, ps.active, ps.guarded, broken, self._was_trusted
                )
                ramp = 1 if self.attribution.by_jump else self._ramp_n
                self.set_position_nominal(not (sensor or self.flow.flow_fault), ramp)
            self.k_loe_hat, self.k_dft_hat, self.k_q_hat = est.k_loe, est.k_dft, est.k_q
        else:
            self.clock.dead_cycle(est.k_loe / est.k_q)
        cmd = self._close(meas)
        if meas.fresh:
            self._was_trusted = self.sensor_trusted and not self.nominal
        sent = cmd.current_a if math.isfinite(cmd.current_a) else 0.0  # as the loop sends it
        self.clock.commanded(sent, meas.command_sent)
        return cmd

    def _rebase(self, theta: float) -> None:
        """:meth:`Estimates.rebase` on ``theta`` while the sensor is trusted (alive through it,
        not guarded): a failed-sensor model leaves x̂ where it is."""
        self.est.rebase(theta, self.sensor_alive(theta) and not self.pos_sup.guarded)

    def observe(self, meas: Measurement) -> None:
        """A sample superseded within this cycle: the sample clock steps the predictors on it."""
        if self.clock.observe(meas, self.est.k_loe / self.est.k_q).gap and self._flow_on:
            self.flow.hold_off(self._flow_hold)

    def _bridge_gain(self) -> float | None:
        """θ̂_D when the position sensor may place x̂ across a redone span: trusted (not guarded,
        not failed) and not under the flow-gain hypothesis; else None."""
        td = self.est.k_dft
        if self.pos_sup.guarded or not self.sensor_alive(td) or self.flow.flow_fault:
            return None
        return td

    def _flow_split(self, meas: Measurement, y_v: float, tl: float) -> None:
        """Load-pressure test: is the position-channel change a flow-gain loss (flowgain.py)?

        Under H_Q the sensor is taken as healthy (k̂_DFT = 1), the current is divided by
        k̂_LOE·k̂_Q with k̂_Q the offset-free increment estimate, and x̂ (in x/k̂_Q units) is
        kept on the sensor so that nothing jumps when the test returns to H_D.
        """
        fl = self.flow
        prod = fl.product(meas.position_m, y_v, self.clock.span, self._spool_hold == 0)
        if self._dead and fl.product_updated:
            self._dead_evidence += 1
        spool_model = self.spool_sup.active
        if spool_model != self._flow_spool_model:
            # the pressure prediction scales with k̂_LOE: evidence taken with another k̂_LOE
            # favours the wrong hypothesis
            self._flow_spool_model = spool_model
            fl.restart()
            fl.hold_off(self._flow_hold)
        # x̂ moves with the creep, in its own units (x/k̂_Q: the sensor read through θ_prod)
        self.est.set_creep(fl.creep.rate_m_s / prod if prod >= self._failed_below else 0.0)
        if (fl.creep.rate_m_s != 0.0) != self._creep_on:
            self._creep_on = not self._creep_on
            self._restart_position(meas.position_m)
        self._spool_age = self._spool_age + 1 if spool_model == self._spool_age_model else 0
        self._spool_age_model = spool_model
        healthy = (
            self._warm_left == 0
            and not self.spool_sup.guarded
            and not self.pos_sup.guarded
            and self._spool_age >= self._baseline_settle
        )
        est = self.est
        fl.update(self.clock.echo, meas.load_pressure_pa, self._flow_theta_l(tl), prod, est.k_dft, healthy)
        if fl.flow_fault:
            est.enter_flow(meas.position_m, prod, tl)
            self._in_flow = True
        elif self._in_flow:  # back to H_D: the product is the sensor's gain (≈ 1 when it vanished)
            self._in_flow = False
            est.leave_flow(meas.position_m, prod)
            self.pos_bank.seed_ria(prod)
            self.pos_sup.force(self.pos_bank.ria)
            est.set_sensor_gain(self.pos_bank.theta[self.pos_bank.ria])

    def _restart_position(self, position_m: float) -> None:
        """The plant model changed (a creep came into use or left it): what the position channel
        concluded under the old model — its models, the guard, the attribution, a flow-gain
        hypothesis — was reached on increments the creep was read into. Start it over from the
        sensor as it reads now (x̂ = y_s, nominal), the spool channel and the creep kept."""
        switches = self.pos_sup.switches
        self.pos_bank.reset()
        self.pos_sup.reset()
        self.pos_sup.switches = switches
        self.attribution.reset()
        self.flow.forget_attribution()
        self.monitor.reset()
        self.est.restart(position_m)
        self.sensor_held_off = self._in_flow = False
        self.set_position_nominal(True, self._ramp_n)

    def _flow_theta_l(self, tl: float) -> float:
        """k̂_LOE for the pressure test: the spool model in use, or while the spool channel is
        still in its warm-up the best-scoring one (a power-on LOE is not switched to yet)."""
        if self._warm_left > 0 or self.spool_sup.guarded:
            j = self.spool_bank.j
            return self.spool_bank.theta[j.index(min(j))]
        return tl

    def _watch(self, tl: float) -> None:
        """The do-no-harm monitor on this sample; nominal compensation while it says so."""
        pb, sb = self.pos_bank, self.spool_bank
        pa, sa = self.pos_sup.active, self.spool_sup.active
        guarded = self._position_guarded()
        est = self.est
        at_limit = (pa >= pb.n_fixed and not guarded and est.k_dft >= self._lim_d_hi) or (
            sa >= sb.n_fixed and not self.spool_sup.guarded and tl <= self._lim_l_lo
        )
        fl = self.flow
        # the position check only where the sensor is read through θ̂_D: under the guard the loop
        # runs on x̂ (no model explains the sensor; θ_prod, fitted on the same sensor, neither)
        fresh = fl.product_fresh and not guarded
        self.set_nominal(self.monitor.update(est.k_dft * est.k_q, fl.theta_prod, fresh, at_limit))

    def fallback_reason(self) -> int:
        """The monitor's reason while in fallback, else 0."""
        return int(self.monitor.reason) if self.monitor.fallback else 0

    def fallback_count(self) -> int:
        """The monitor's fallbacks since start-up."""
        return self.monitor.fallbacks

    def _position_guarded(self) -> bool:
        return self.pos_sup.guarded and not self.flow.flow_fault

    def _guarded_gain(self) -> float | None:
        """x̂ carries the loop under the guard only while the sensor gives no better reading.
        The guard says no level model explains the sensor against x̂; x̂ integrates the spool at
        the model's flow gain, so on a plant off the model, or after a flow-gain change beside a
        sensor fault, x̂ is the one that is off. Once the sensor's increments have followed the
        spool for a full window (M excited increments) since the guard rose, at a live gain and
        settled, and it is not dead, it is read through the gain the evidence gives it: the
        gain its last jump went to, else θ_prod when the deviation was attributed to the sensor,
        else 1 (raw, as the plain PI loop reads it)."""
        if not self._flow_on:  # no increment evidence kept (the flow-gain test is off)
            return None
        fl, att = self.flow, self.attribution
        if (
            not (self._dead or fl.creep.judged or att.jumped_since_guard)
            and fl.still_samples < self._moving_samples
        ):
            # before the creep is known, x̂ has no authority over a moving sensor that gave no
            # sign of a fault (a jump, standing still)
            return 1.0
        if self._dead or not (fl.product_fresh and fl.product_settled and fl.theta_prod >= self._alive):
            return None
        if att.since_guard < fl.increment_window:
            return None
        if math.isfinite(att.jump_gain) and att.jump_gain >= self._alive:
            return att.jump_gain
        return fl.theta_prod if fl.sensor_favoured else 1.0

    def _sensor_live(self) -> bool:
        """The sensor follows the spool, so it may be fed back raw. Under the position guard
        with no jump of the reading since the guard rose (a flow-gain change or a slow drift:
        x̂, integrating at the nominal flow gain, is the suspect, not the sensor): θ_prod, fresh
        or not (no motion is no evidence against it), at ``follows_factor`` times the
        failed-sensor threshold or more. Otherwise θ_prod must be fresh, at a live sensor's
        gain and settled, and after a jump (a drift step, a failure) have taken a full window
        (M excited increments) since the guard rose: increments spanning the jump are not
        evidence that the sensor follows the spool. Never while the sensor is dead."""
        fl = self.flow
        if self._dead:
            return False
        guarded = self.pos_sup.guarded
        att = self.attribution
        if guarded and not att.jumped_since_guard:
            return fl.theta_prod >= self._follows * self._failed_below
        if not (fl.product_fresh and fl.theta_prod >= self._alive):
            return False
        if guarded and att.since_guard < fl.increment_window:
            return False
        return fl.product_settled

    def _sensor_dead(self) -> bool:
        """Found standing still through a full-flow stop phase (:class:`StillSensor`) and not
        seen following the spool since: θ_prod, over a full window (M excited increments) of
        increments taken after the finding, at a live sensor's gain."""
        if self._dead and self._dead_evidence >= self.flow.increment_window and self._sensor_follows_spool():
            self._dead = False
        return self._dead

    def _sensor_follows_spool(self) -> bool:
        """The offset-free increment estimate θ_prod (fresh) says the sensor moves with the
        spool integral, at ``follows_factor`` times the failed-sensor threshold or more."""
        fl = self.flow
        return fl.product_fresh and fl.theta_prod >= self._follows * self._failed_below

    def index_values(self) -> list[float]:
        """J of the spool models then the position models."""
        return self.spool_bank.j + self.pos_bank.j

    def theta_values(self) -> list[float]:
        """θ of the spool models then the position models."""
        return self.spool_bank.theta + self.pos_bank.theta

    def probe(self) -> tuple[int, int, float, float]:
        """Active slots of both channels and the estimates in use."""
        return (
            SPOOL_SLOT0 + self.spool_sup.active,
            POSITION_SLOT0 + self.pos_sup.active,
            self.k_loe_hat,
            self.k_dft_hat,
        )

    def switch_count(self) -> int:
        """Switches of both channels."""
        return self.spool_sup.switches + self.pos_sup.switches
