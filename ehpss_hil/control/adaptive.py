"""The adaptive modes: ``mmac`` (per-channel banks) and ``smac``/``mmac-paper`` (joint model).

``mmac`` (DESIGN §5): the spool channel ``y_v = θ_L·v`` (v: commanded spool predicted from the
current echo) and the position channel ``y_s = θ_D·x̂`` (x̂: model position from the spool LVDT),
each with fixed models + FRA + RIA, a supervisor and a guard. The spool residual depends on
k_LOE only and the position residual on k_DFT only, which is what makes them separable.

``mmac-paper``/``smac``: the paper's sensing — the position alone. The regression is over a
window of M samples, ``y = y_s[k] − y_s[k−M]`` against ``φ = K_c·∫_{k−M}^{k} v dt``, i.e.
``y = k_LOE·k_DFT·φ``: only the product is identifiable, so a joint (θ_L, θ_D) model cannot tell a
50 % LOE from a 0.5 drift (DESIGN §4). ``mmac-paper`` has the fixed pairs nominal, LOE 50 %,
drift 0.5 plus FRA and RIA, whose adaptive law (the paper's actuator parametrization) adapts θ_L
with θ_D held (FRA: 1; RIA: the θ_D of the fixed model it was reinitialized to); ``smac`` has one
adaptive model, θ_L with θ_D = 1. Their x̂ integrates θ̂_L·v (no spool sensor in this sensing).
"""

from __future__ import annotations

import math
from collections import deque

from .bank import JointBank, ScalarBank
from .base import Measurement, NominalMotion, ValveCommand
from .controllers import JOINT_SLOT0, POSITION_SLOT0, SMAC_SLOT, SPOOL_SLOT0, LoopBase
from .estimator import Nlms, per_sample_gain
from .flowgain import FlowGainMonitor
from .monitor import HarmMonitor
from .supervisor import Supervisor
from .tuning import ControlTuning

#: after samples stepped without their data the flow-gain test takes no evidence for this many
#: samples (≈ 6 time constants of the slowest valve/cylinder pole, −284 s⁻¹, at 1 kHz)
FLOW_HOLD_S = 0.02
#: the predictors are redone over at most this many sensor samples and after fewer cycles without
#: data (beyond: dead-reckoned and re-anchored): the 4-bit counter tells up to 15 apart
RESYNC_SAMPLES = 15
#: the commands kept: those applied over every sample of the longest span redone (one sample of
#: transport delay: the command computed at cycle c is applied over [c+1, c+2), DESIGN §9)
WIRE_COMMANDS = RESYNC_SAMPLES + 2
#: the kept commands are taken as what the valve applied when the echo of a span's last sample
#: is the one kept for it within this (A): the DBC's 10 µA steps, the setpoint and echo scalings
WIRE_MATCH_A = 3e-5
#: the position sensor may move x̂ across a span within this multiple of the bound that the spool
#: LVDT at its two ends leaves (:func:`bridge_bound_m`)
BRIDGE_MARGIN = 1.25
#: after the spool was at its stop the spool channel and the flow-gain test take no evidence for
#: this long (s): the valve model's stop is placed with k̂_LOE, the plant's with k_LOE, and the
#: difference dies out with the valve poles (≈ 0.6 ms time constant)
SPOOL_STOP_HOLD_S = 0.005
#: an adaptive estimate within this of its clip counts as at its limit (dimensionless)
AT_LIMIT_MARGIN = 0.01


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
        self.spool_sup = Supervisor(self.spool_bank, t, ts, guard_epsilon=t.guard_epsilon,
                                    sustained_guard=True)
        self.pos_sup = Supervisor(self.pos_bank, t, ts, guard_epsilon=t.position_guard_epsilon)
        self.flow = FlowGainMonitor(self.params.plant, ts, self.scale_spool_m, t)
        self.monitor = HarmMonitor(t.flow_gain_min_deviation, t.increment_window,
                                   round(t.monitor_confirm_s / ts), round(t.monitor_reengage_s / ts),
                                   t.sensor_failed_below, t.monitor_sensor_alive)
        self._lim_d_hi = t.k_dft_limits[1] - AT_LIMIT_MARGIN
        self._lim_l_lo = t.k_loe_limits[0] + AT_LIMIT_MARGIN
        self._in_flow = False
        self._flow_on = t.flow_gain_test
        self._flow_hold = max(1, round(FLOW_HOLD_S / ts))
        self._stop_hold = max(1, round(SPOOL_STOP_HOLD_S / ts))
        self._inv_s_spool = 1.0 / self.scale_spool_m
        self._inv_s_pos = 1.0 / self.scale_pos_m
        n_l, n_d = len(t.fixed_k_loe) + 2, len(t.fixed_k_dft) + 2
        self.index_slots = (tuple(range(SPOOL_SLOT0, SPOOL_SLOT0 + n_l))
                            + tuple(range(POSITION_SLOT0, POSITION_SLOT0 + n_d)))

    def _reset_mode(self) -> None:
        self.spool_bank.reset()
        self.pos_bank.reset()
        self.spool_sup.reset()
        self.pos_sup.reset()
        self.flow.reset()
        self.monitor.reset()
        self._in_flow = False
        self._flow_spool_model = self.spool_sup.active
        self._dead = 0
        #: x̂ starts on the first sensor sample after a reset (θ̂_D = 1 then): a reset on leaving
        #: the fail-safe comes mid-motion, and x̂ from 0 put the position channel in guard at once,
        #: the loop fed back x̂ and drove the plant away (a realtime run: 3 mm)
        self._seed = True
        self._span = 1  # sensor samples this fresh cycle stands for (when redone on them)
        self._observed = 0  # … of the superseded samples observed before it in this cycle
        #: the current commanded in each of the last cycles (A), as held by the valve: a cycle whose
        #: command is not sent repeats the previous one
        self._wire: deque[float] = deque([0.0] * WIRE_COMMANDS, maxlen=WIRE_COMMANDS)
        self._y_seen = 0.0  # the position sensor at the last sample seen (m)
        self._spool_hold = 0  # samples left without spool evidence (the spool was at its stop)

    def step(self, meas: Measurement) -> ValveCommand:
        """Predict, score both banks, supervise, compensate, PI."""
        if meas.fresh:
            y_v = meas.spool_m
            tl_prev = self.k_loe_hat / self.k_q_hat
            self.valve.stop_m = self.stroke_m / max(tl_prev, self.min_theta_l)
            gap, resync, v, xh = self._advance(meas, True)
            if self._seed:  # the first sample since a reset: the plant is where the sensor says
                self._seed = False
                xh = self.xhat.x = meas.position_m
            self._span, self._observed = self._observed + (meas.samples if resync else 1), 0
            sb, ss = self.spool_bank, self.spool_sup
            lvl = self._stop_level_m
            if (y_v >= lvl or y_v <= -lvl or abs(tl_prev * v) >= lvl
                    or (gap and not resync)):
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
            pb, ps = self.pos_bank, self.pos_sup
            if (gap and not resync) or stopped:
                # x̂ missed samples, was dead-reckoned, or integrated a spool slamming into its
                # stop (a transient no model of the valve follows exactly)
                td = self.k_dft_hat
                if (not self.pos_sup.guarded and td >= self._failed_below
                        and not self.flow.flow_fault):
                    # re-anchor on the trusted sensor (a dead-reckoned offset must not be taken
                    # for a drift by the position bank) and skip this sample's regression
                    xh = self.xhat.x = meas.position_m / td
                elif not self.flow.flow_fault:
                    pb.update(meas.position_m, xh)
                    ps.update(abs(xh) * self._inv_s_pos)
            elif not self.flow.flow_fault:  # under H_Q the position channel has nothing to explain
                pb.update(meas.position_m, xh)
                ps.update(abs(xh) * self._inv_s_pos)
            tl = 1.0 if ss.guarded else sb.theta[ss.active]
            self.k_loe_hat = tl
            self.k_dft_hat = pb.theta[ps.active]
            self.k_q_hat = 1.0
            if self._flow_on:
                self._flow_split(meas, y_v, tl)
                self._watch(tl)
        else:
            if self._dead == 0:  # the predictors' state at the last sample seen
                self.valve.mark()
                self.xhat.mark()
                self.flow.mark()
            self._dead += 1
            current = self._wire[-2]  # applied over the last sample: sent 2 cycles ago
            v = self.valve.step(current)
            self.xhat.integrate(self.k_loe_hat / self.k_q_hat * v)
            if self._flow_on:
                self.flow.propagate(current)
        cmd = self._close(meas)
        sent = cmd.current_a if math.isfinite(cmd.current_a) else 0.0  # as the loop sends it
        self._wire.append(sent if meas.command_sent else self._wire[-1])
        return cmd

    def observe(self, meas: Measurement) -> None:
        """A sample superseded within this cycle: valve model, x̂ and the pressure model step on
        it (its own spool LVDT and current echo), so the next sample is 1 on from it."""
        _, resync, _, _ = self._advance(meas, False)
        self._observed += meas.samples if resync else 1
        if self._flow_on:
            self.flow.propagate(meas.coil_current_a)

    def _advance(self, meas: Measurement, stepped: bool) -> tuple[bool, bool, float, float]:
        """Valve model and x̂ up to this fresh sample (``stepped``: the cycle's own sample, not
        one superseded within it). ``gap``: samples were missed or cycles ran without data since
        the last one seen (the flow-gain test then takes no evidence for a while); ``resync``:
        the predictors were redone over every sample since (see :meth:`_resync`). Returns
        (gap, resync, v, x̂) (v, x̂ in m)."""
        dead, self._dead = self._dead, 0
        gap = dead > 0 or meas.samples > 1
        if gap and self._flow_on:
            self.flow.hold_off(self._flow_hold)
        if self._resync(meas.samples, dead):
            v, xh = self._predict_span(meas, dead, stepped)
            out = gap, True, v, xh
        else:
            self._echo = meas.coil_current_a
            out = gap, False, self.valve.step(self._echo), self.xhat.integrate(meas.spool_m)
        self._y_seen = meas.position_m
        return out

    @staticmethod
    def _resync(samples: int, dead: int) -> bool:
        """Should the predictors be redone on the sensor's sample clock? Whenever the sensor
        samples since the last one seen differ from one, or cycles without data lie between
        (``dead``), as long as both spans are < 16 (the counter's wrap): a realtime slip, samples
        superseded within one cycle, lost frames, a stall of either process (over which the
        emulator holds one command: the echo that ends it). Longer gaps keep the dead-reckoned
        x̂ and re-anchor it."""
        if samples <= 0 or (samples == 1 and dead == 0):
            return False
        return samples <= RESYNC_SAMPLES and dead < RESYNC_SAMPLES

    def _predict_span(self, meas: Measurement, dead: int, stepped: bool) -> tuple[float, float]:
        """Valve model and x̂ stepped over ``meas.samples`` sensor samples from the last one seen
        (the dead-reckoned steps of the ``dead`` cycles without data undone). Returns (v, x̂) (m).

        Currents over the samples not seen: :func:`span_currents` (the commands sent, when this
        sample's echo confirms them). The valve model's spool, times k̂_LOE, is corrected by the
        spool LVDT at both ends (:func:`bridge_spool`); where the two ends disagree (k_LOE
        changed) the position sensor places x̂ within the bound they leave
        (:func:`bridge_bound_m`), while it is trusted."""
        valve, xh, flow = self.valve, self.xhat, self.flow
        if dead:
            valve.rewind()
            xh.rewind()
            flow.rewind()
        n, echo_a, y_v = meas.samples, meas.coil_current_a, meas.spool_m
        currents = span_currents(n, dead, self._wire if stepped else None, self._echo, echo_a)
        gain, x0 = self.k_loe_hat / self.k_q_hat, xh.x
        e0 = xh.last_spool - gain * valve.v
        vs = []
        for c in currents:
            vs.append(valve.step(c))
            if self._flow_on:  # the pressure model too (its update steps this sample)
                flow.propagate(c)
        self._echo = echo_a
        v = valve.step(echo_a)
        en = y_v - gain * v
        for sp in bridge_spool(vs, gain, e0, en):
            xh.integrate(sp)
        x_end = xh.integrate(y_v)
        td = self.k_dft_hat
        if (n > 1 and not self._seed and not self.pos_sup.guarded and td >= self._failed_below
                and not self.flow.flow_fault):
            u = BRIDGE_MARGIN * bridge_bound_m(xh.spool_to_x_m(1.0, n - 1), en - e0)
            dx = (meas.position_m - self._y_seen) / td
            xh.x = x0 + min(max(dx, x_end - x0 - u), x_end - x0 + u)
        return v, xh.x

    def _flow_split(self, meas: Measurement, y_v: float, tl: float) -> None:
        """Load-pressure test: is the position-channel change a flow-gain loss (flowgain.py)?

        Under H_Q the sensor is taken as healthy (k̂_DFT = 1), the current is divided by
        k̂_LOE·k̂_Q with k̂_Q the offset-free increment estimate, and x̂ (in x/k̂_Q units) is
        kept on the sensor so that nothing jumps when the test returns to H_D.
        """
        fl = self.flow
        prod = fl.product(meas.position_m, y_v, self._span, self._spool_hold == 0)
        spool_model = self.spool_sup.active
        if spool_model != self._flow_spool_model or self._warm_left > 0:
            # the pressure prediction scales with k̂_LOE: evidence taken with another (or a not yet
            # identified) k̂_LOE favours the wrong hypothesis
            self._flow_spool_model = spool_model
            fl.restart()
            fl.hold_off(self._flow_hold)
        fl.update(self._echo, meas.load_pressure_pa, tl, prod)
        if fl.flow_fault:
            self.k_q_hat = prod
            self.k_loe_hat = tl * prod
            self.k_dft_hat = 1.0
            self.xhat.x = meas.position_m / prod
            self._in_flow = True
        elif self._in_flow:  # back to H_D: the product is the sensor's gain (≈ 1 when it vanished)
            self._in_flow = False
            self.xhat.x = meas.position_m / prod if prod >= self._failed_below else meas.position_m
            self.pos_bank.seed_ria(prod)
            self.pos_sup.force(self.pos_bank.ria)
            self.k_dft_hat = self.pos_bank.theta[self.pos_bank.ria]

    def _watch(self, tl: float) -> None:
        """The do-no-harm monitor on this sample; nominal compensation while it says so."""
        pb, sb = self.pos_bank, self.spool_bank
        pa, sa = self.pos_sup.active, self.spool_sup.active
        guarded = self._position_guarded()
        at_limit = ((pa >= pb.n_fixed and not guarded and self.k_dft_hat >= self._lim_d_hi)
                    or (sa >= sb.n_fixed and not self.spool_sup.guarded and tl <= self._lim_l_lo))
        fl = self.flow
        # the position check only where the sensor is read through θ̂_D: under the guard the loop
        # runs on x̂ (no model explains the sensor; θ_prod, fitted on the same sensor, neither)
        fresh = fl.product_fresh and not guarded
        self.set_nominal(self.monitor.update(self.k_dft_hat * self.k_q_hat, fl.theta_prod,
                                             fresh, at_limit))

    def fallback_reason(self) -> int:
        """The monitor's reason while in fallback, else 0."""
        return int(self.monitor.reason) if self.monitor.fallback else 0

    def fallback_count(self) -> int:
        """The monitor's fallbacks since start-up."""
        return self.monitor.fallbacks

    def _position_guarded(self) -> bool:
        return self.pos_sup.guarded and not self.flow.flow_fault

    def index_values(self) -> list[float]:
        """J of the spool models then the position models."""
        return self.spool_bank.j + self.pos_bank.j

    def theta_values(self) -> list[float]:
        """θ of the spool models then the position models."""
        return self.spool_bank.theta + self.pos_bank.theta

    def probe(self) -> tuple[int, int, float, float]:
        """Active slots of both channels and the estimates in use."""
        return (SPOOL_SLOT0 + self.spool_sup.active, POSITION_SLOT0 + self.pos_sup.active,
                self.k_loe_hat, self.k_dft_hat)

    def switch_count(self) -> int:
        """Switches of both channels."""
        return self.spool_sup.switches + self.pos_sup.switches


class JointController(LoopBase):
    """``mmac-paper`` (joint bank + supervisor) or ``smac`` (one joint adaptive model)."""

    def __init__(self, tuning: ControlTuning, reference: NominalMotion | None, mode: str) -> None:
        super().__init__(tuning, reference)
        self.mode = mode

    def _build(self) -> None:
        t, ts = self.tuning, self.ts_s
        m = t.increment_window
        self._m = m
        k_c = self.params.plant.velocity_gain_1_s
        self._h = 0.5 * ts * k_c
        scale = self.scale_spool_m * k_c * ts * m
        self._inv_s = 1.0 / scale
        g = per_sample_gain(t.nlms_gain_per_ms, ts)
        if self.mode == "smac":
            c = (t.nlms_c_fraction * scale) ** 2
            self.est = Nlms(1.0, g, c, t.k_loe_limits[0], t.k_loe_limits[1])
            self.index_slots = (SMAC_SLOT,)
        else:
            fixed = ((1.0, 1.0), (0.5, 1.0), (1.0, 0.5))
            self.bank = JointBank(fixed, t, ts, scale, g)
            self.sup = Supervisor(self.bank, t, ts)
            self.index_slots = tuple(range(JOINT_SLOT0, JOINT_SLOT0 + 5))

    def _reset_mode(self) -> None:
        self._ys = [0.0] * self._m
        self._vs = [0.0] * self._m
        self._i = 0
        self._n = 0
        self._int_v = 0.0
        self._v_prev = 0.0
        if self.mode == "smac":
            self.est.reset()
        else:
            self.bank.reset()
            self.sup.reset()

    def step(self, meas: Measurement) -> ValveCommand:
        """Windowed increment regression, (bank + supervisor | single model), compensation."""
        if meas.fresh:
            self._echo = meas.coil_current_a
        v = self.valve.step(self._echo)
        self._int_v += self._h * (v + self._v_prev)
        self._v_prev = v
        self.xhat.integrate(self.k_loe_hat * v)
        i = self._i
        y = meas.position_m - self._ys[i]
        phi = self._int_v - self._vs[i]
        self._ys[i] = meas.position_m
        self._vs[i] = self._int_v
        self._i = (i + 1) % self._m
        self._n += 1
        if meas.fresh and self._n > self._m:
            self._adapt(y, phi)
        return self._close(meas)

    def _adapt(self, y: float, phi: float) -> None:
        if self.mode == "smac":
            self.est.update(y, phi)
            self.k_loe_hat = self.est.theta
        else:
            self.bank.update(y, phi)
            a = self.sup.update(abs(phi) * self._inv_s)
            self.k_loe_hat, self.k_dft_hat = self.bank.pairs[a]

    def index_values(self) -> list[float]:
        """J per model (smac: none is computed; reported as 0)."""
        return [0.0] if self.mode == "smac" else list(self.bank.j)

    def theta_values(self) -> list[float]:
        """θ_L·θ_D per model."""
        if self.mode == "smac":
            return [self.est.theta]
        return [a * b for a, b in self.bank.pairs]

    def probe(self) -> tuple[int, int, float, float]:
        """The joint slot is reported for both channels."""
        s = SMAC_SLOT if self.mode == "smac" else JOINT_SLOT0 + self.sup.active
        return (s, s, self.k_loe_hat, self.k_dft_hat)

    def switch_count(self) -> int:
        """Switches of the joint supervisor."""
        return 0 if self.mode == "smac" else self.sup.switches


def span_currents(samples: int, dead: int, wire: deque[float] | None, last_echo_a: float,
                  echo_a: float) -> list[float]:
    """The currents (A) applied over the ``samples − 1`` samples not seen before one whose echo
    is ``echo_a`` (the last one seen had ``last_echo_a``; ``dead`` cycles ran without data in
    between). ``wire``: the commands sent in the cycles before this one (newest last; one sample
    of transport delay, so the echo of this sample is ``wire[-2]``). They are taken when each
    sample not seen had a cycle of its own (``dead == samples − 1``) and this echo confirms the
    valve applied them: the sensor frames were lost, the commands got through. Otherwise (fewer
    cycles than samples: the emulator was late; or no ``wire``: a sample superseded within a
    cycle): the last echo for the first period (commanded before that sample) and this echo for
    the others (a late emulator holds the newest command over the periods it skips)."""
    if samples < 2:
        return []
    if (wire is not None and dead == samples - 1
            and abs(echo_a - wire[-2]) <= WIRE_MATCH_A):
        return [wire[-m - 2] for m in range(samples - 1, 0, -1)]
    return [last_echo_a] + [echo_a] * (samples - 2)


def bridge_spool(v_m: list[float], gain: float, e_start_m: float, e_end_m: float) -> list[float]:
    """The spool (m) at the samples not seen between two spool LVDT readings: the model's
    ``gain·v`` plus its error ``y_v − gain·v`` at the two readings, interpolated linearly over
    the span (``len(v_m) + 1`` periods). A gain that changed before the span (a k̂_LOE not yet
    converged) leaves the same error at both ends and is removed whole; one that changed inside
    it is split as if at the middle, the expectation over where in the span it changed. Without
    the ends, the model alone left x̂ off by (k_LOE − k̂_LOE)·∫v over the span, and the position
    bank took that offset for a drift (a 14-sample blackout at the LOE onset of case 3: θ̂_D
    0.78 for 0.8, 9.5 µm RMS for 0.84)."""
    n = len(v_m) + 1
    de = (e_end_m - e_start_m) / n
    return [gain * v + e_start_m + de * (j + 1) for j, v in enumerate(v_m)]


def bridge_bound_m(x_per_spool: float, de_m: float) -> float:
    """How far (m) x̂ bridged by :func:`bridge_spool` can be from the truth when the spool error
    changed by ``de_m`` (m) in one step somewhere in the span: the linear interpolation is off
    by at most half the step over the samples not seen; ``x_per_spool`` is x̂'s change per metre
    of spool held over them (m/m)."""
    return 0.5 * x_per_spool * abs(de_m)
