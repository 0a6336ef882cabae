"""The ``mmac`` mode: per-channel banks on the spool LVDT and the position sensor.

``mmac`` (docs/design.md §5): the spool channel ``y_v = θ_L·v`` (v: commanded spool predicted from the
current echo) and the position channel ``y_s = θ_D·x̂`` (x̂: model position from the spool LVDT),
each with fixed models + FRA + RIA, a supervisor and a guard. The spool residual depends on
k_LOE only and the position residual on k_DFT only, which is what makes them separable. Whose a
position-channel change is, and whether compensating does harm, is the evidence layer's
(:mod:`.evidence`); the estimator state has one owner (:class:`.Estimates`). One fresh sample:
sample clock → spool bank → (still sensor) → position bank → evidence → estimates → close. The
paper's joint-model modes (``smac``, ``mmac-paper``) are in :mod:`.joint`.
"""

from __future__ import annotations

from .bank import ScalarBank
from .base import Measurement, ValveCommand
from .controllers import POSITION_SLOT0, SPOOL_SLOT0, LoopBase
from .estimates import Estimates
from .estimator import per_sample_gain
from .evidence import EvidenceLayer
from .sampleclock import SampleClock
from .supervisor import Supervisor


class MmacController(LoopBase):
    """Corrected MMAC on two channels (spool, position) with bumpless compensation."""

    mode = "mmac"
    warmup_tracks_sensor = False

    # the mode's own attributes as slots too (LoopBase)
    __slots__ = (
        "_flow_on",
        "_inv_s_pos",
        "_inv_s_spool",
        "_pressure",
        "_spool_hold",
        "_stop_hold",
        "_was_trusted",
        "clock",
        "est",
        "evidence",
        "index_slots",
        "pos_bank",
        "pos_sup",
        "spool_bank",
        "spool_sup",
    )

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
        self.est = Estimates(self.xhat, t.sensor_failed_below, t.rebase_limit * self.scale_pos_m)
        self.clock = SampleClock(self.valve, self.xhat, None, t)
        self.evidence = EvidenceLayer(
            self.params.plant,
            ts,
            self.scale_spool_m,
            t,
            self.est,
            (self.spool_bank, self.spool_sup),
            (self.pos_bank, self.pos_sup),
            self.clock,
        )
        self._pressure = self.evidence.pressure
        if t.flow_gain_test:  # the sample clock steps the pressure model too
            self.clock.pressure = self._pressure.model
        self._flow_on = t.flow_gain_test
        self._stop_hold = max(1, round(t.spool_stop_hold_s / ts))
        self._inv_s_spool = 1.0 / self.scale_spool_m
        self._inv_s_pos = 1.0 / self.scale_pos_m
        n_l, n_d = len(t.fixed_k_loe) + 2, len(t.fixed_k_dft) + 2
        self.index_slots = tuple(range(SPOOL_SLOT0, SPOOL_SLOT0 + n_l)) + tuple(
            range(POSITION_SLOT0, POSITION_SLOT0 + n_d)
        )

    def _reset_mode(self) -> None:
        self.spool_bank.reset()
        self.pos_bank.reset()
        self.spool_sup.reset()
        self.pos_sup.reset()
        self.evidence.reset()
        self._was_trusted = True  # the last fresh sample fed the sensor back, not on the fallback
        self.clock.reset()
        self.est.reset()
        self._spool_hold = 0  # samples left without spool evidence (the spool was at its stop)

    def step(self, meas: Measurement) -> ValveCommand:
        """Sample clock → spool bank → position bank → evidence → estimates → close.

        This runs on every cycle: attributes are read once into locals, and the one-line
        questions (:meth:`sensor_alive`, :meth:`_bridge_gain`, the no-change test of
        :meth:`set_nominal`) are written out."""
        est, clock = self.est, self.clock
        if meas.fresh:
            tl_prev = est.k_loe / est.k_q
            lim = self.min_theta_l
            self.valve.stop_m = self.stroke_m / (lim if lim > tl_prev else tl_prev)  # max(tl_prev, lim)
            ps, pt = self.pos_sup, self._pressure
            failed_below = self._failed_below
            td = est.theta_d  # _bridge_gain(): θ̂_D when the sensor may place x̂, else None
            trusted = not ps.guarded and td >= failed_below and not self.sensor_held_off
            seeding = clock.seed
            gap, resync, v, xh = clock.tick(meas, tl_prev, td if trusted and not pt.flow_fault else None)
            if seeding:
                est.seed(meas.position_m)
            if gap:
                self.evidence.gap()
            broken = gap and not resync
            self._banks(meas, v, xh, tl_prev, broken)
            ss = self.spool_sup
            tl = 1.0 if ss.guarded else self.spool_bank.theta[ss.active]
            td = self.pos_bank.theta[ps.active]
            alive = td >= failed_below and not self.sensor_held_off and not ps.guarded
            rebase = alive
            if alive and self.position_nominal and td != pt.k_base:
                # a model the loop does not read the sensor through moves x̂ only as far as a
                # returning sensor may stand off it: x̂ takes the loop if the sensor fails
                rebase = abs(meas.position_m - est.k_q * est.rebased_x(td)) <= self._return_gap_m
            est.set_channels(tl, td, rebase, pt.k_base)
            if est.y0 != 0.0 and alive and not pt.flow_fault and self._pivot_model(td):
                # the nominal model in use, or the gain a verified jump of the reading went to:
                # once the increments confirm it, the reading is θ̂_D times the piston, and the
                # position regression goes through the sensor's zero
                if self.evidence.inc.confirms(td):
                    est.pivot_to_zero(td)
            if self._flow_on:
                att = self.evidence.update(
                    meas, tl, self._spool_hold == 0, self._warm_left > 0, broken, self._was_trusted
                )
                if att.restarted:  # the raw sensor, not held off, after a restart
                    self.sensor_held_off = False
                    self.set_position_nominal(True, self._ramp_n)
                if att.fallback != self.nominal:
                    self.set_nominal(att.fallback)
                if att.position_nominal != self.position_nominal:
                    self.set_position_nominal(att.position_nominal, att.ramp_samples)
            self.k_loe_hat, self.k_dft_hat, self.k_q_hat = est.k_loe, est.k_dft, est.k_q
        else:
            clock.dead_cycle(est.k_loe / est.k_q)
        cmd = self._close(meas)
        if meas.fresh:
            self._was_trusted = self.sensor_trusted and not self.nominal
        clock.commanded(self._sent, meas.command_sent)  # _finish's current, as the loop sends it
        return cmd

    def _pivot_model(self, theta_d: float) -> bool:
        """The position model in use may carry the regression through the sensor's zero: it is
        the nominal one (θ̂_D = k_base), or within ``flow_gain_min_deviation`` of the product a
        jump of the reading was verified at (a gain change scales the reading about its zero).
        Not on a model the pressure test alone attributed: on a single rod the increments
        "confirm" a different gain in each direction of travel."""
        ev = self.evidence
        if theta_d == ev.pressure.k_base:
            return True
        return abs(theta_d - ev.attribution.verified_gain) < ev.pressure.min_deviation

    def _banks(self, meas: Measurement, v: float, xh: float, tl_prev: float, broken: bool) -> None:
        """Both banks on this sample (v: the commanded spool, xh: x̂, m). The spool bank takes
        no evidence at or just off the spool's stop, nor after a gap the predictors could not
        redo (``broken``: the valve model was dead-reckoned), until the model's error has died
        out. The still sensor watches the stop phases. The position bank has nothing to explain
        under H_Q; after x̂ missed samples, was dead-reckoned, or integrated a spool slamming
        into its stop (a transient no model of the valve follows exactly) it re-anchors on the
        trusted sensor and starts over from here (a dead-reckoned offset is no drift)."""
        y_v, pos = meas.spool_m, meas.position_m
        lvl = self._stop_level_m
        at_stop = y_v >= lvl or y_v <= -lvl
        ev = self.evidence
        if at_stop or abs(tl_prev * v) >= lvl or broken:
            self._spool_hold = self._stop_hold
            ev.spool_stop()
        hold = self._spool_hold
        stopped = hold > 0
        if stopped:  # at or just off the stop: not evidence of k_LOE
            self._spool_hold = hold - 1
        else:
            self.spool_bank.update(y_v, v)
            self.spool_sup.update(abs(v) * self._inv_s_spool)
        if ev.stop_phase(at_stop, y_v, pos, xh):
            self.sensor_held_off = True  # found dead: held off, x̂ placed (Estimates.place_dead)
            xh = self.xhat.x
        est = self.est
        flow = self._pressure.flow_fault
        if broken or stopped:
            td = est.theta_d
            if not self.pos_sup.guarded and self.sensor_alive(td) and not flow:
                est.reanchor(pos, xh)
                est.rebase(td, True)  # trusted: checked just above
                return
        if not flow:
            dx = xh - est.x0
            self.pos_bank.update(pos - est.y0, dx)
            self.pos_sup.update(abs(dx) * self._inv_s_pos)

    def observe(self, meas: Measurement) -> None:
        """A sample superseded within this cycle: the sample clock steps the predictors on it."""
        if self.clock.observe(meas, self.est.k_loe / self.est.k_q).gap:
            self.evidence.gap()

    # ---- the loop's questions, answered by the evidence ----------------------------------
    def _position_guarded(self) -> bool:
        return self.evidence.position_guarded()

    def _guarded_gain(self) -> float | None:
        return self.evidence.guarded_gain()

    def _jumped_under_guard(self) -> bool:
        return self.evidence.jumped_under_guard()

    def _sensor_live(self) -> bool:
        return self.evidence.sensor_live()

    def _sensor_dead(self) -> bool:
        return self.evidence.sensor_dead()

    def _sensor_follows_spool(self) -> bool:
        return self.evidence.sensor_follows_spool()

    def _bridge_gain(self) -> float | None:
        """θ̂_D when the position sensor may place x̂ across a redone span: trusted (not guarded,
        not failed) and not under the flow-gain hypothesis; else None."""
        td = self.est.theta_d
        if self.pos_sup.guarded or not self.sensor_alive(td) or self._pressure.flow_fault:
            return None
        return td

    def fallback_reason(self) -> int:
        """The monitor's reason while in fallback, else 0."""
        mon = self.evidence.monitor
        return int(mon.reason) if mon.fallback else 0

    def fallback_count(self) -> int:
        """The monitor's fallbacks since start-up."""
        return self.evidence.monitor.fallbacks

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

    def sample_record(self) -> tuple[float, ...]:
        """:meth:`probe` then :meth:`index_values` in one tuple, built at once (every sample of
        a simulation)."""
        return (
            SPOOL_SLOT0 + self.spool_sup.active,
            POSITION_SLOT0 + self.pos_sup.active,
            self.k_loe_hat,
            self.k_dft_hat,
            *self.spool_bank.j,
            *self.pos_bank.j,
        )

    def switch_count(self) -> int:
        """Switches of both channels."""
        return self.spool_sup.switches + self.pos_sup.switches
