"""The predictors on the sensor's sample clock: late, lost and superseded samples in, a regular
stream out.

A realtime loop's cycles slip against the sensor's samples: a frame arrives late, is lost, or is
superseded by a newer one within the same cycle; either process stalls. The valve model, the
model position x̂ and the load-pressure model must nevertheless advance once per *sensor sample*
with what the valve really applied over it. :class:`SampleClock` does that, so that the banks
downstream see one prediction per sample as if no sample had slipped:

* a cycle without data dead-reckons the predictors on the command sent two cycles before (one
  sample of transport delay) and marks where they stood at the last sample seen;
* the next sample redoes them from that mark over every sample that passed (``Measurement.samples``
  from the E2E counter), up to :data:`RESYNC_SAMPLES` (the counter tells up to 15 apart): the
  currents over the samples not seen are the commands sent when this sample's echo confirms them
  (:func:`span_currents`), the spool between the two LVDT readings is the model's corrected by
  the readings at both ends (:func:`bridge_spool`), and the position sensor places x̂ within the
  bound those ends leave (:func:`bridge_bound_m`) when the caller trusts it;
* a sample superseded within a cycle is stepped on its own data (:meth:`SampleClock.observe`);
* longer gaps keep the dead-reckoned state; the caller re-anchors x̂ and takes no evidence.

The clock knows nothing of frames or banks: it is given measurements and gains, and reports per
sample whether it had a gap and whether it redid the span.
"""

from __future__ import annotations

from collections import deque
from typing import NamedTuple, Protocol

from .base import Measurement
from .predictors import ModelPosition, ValvePredictor
from .tuning import ControlTuning

#: the predictors are redone over at most this many sensor samples and after fewer cycles without
#: data (beyond: dead-reckoned and re-anchored): the 4-bit counter tells up to 15 apart. Not a
#: gate: the protocol's reach (the driver, the watchdog and replay share it)
RESYNC_SAMPLES = 15
#: the commands kept: those applied over every sample of the longest span redone (one sample of
#: transport delay: the command computed at cycle c is applied over [c+1, c+2))
WIRE_COMMANDS = RESYNC_SAMPLES + 2


class PressureModel(Protocol):
    """A third predictor stepped on the applied current (the flow-gain test's P_L model)."""

    def propagate(self, current_a: float) -> None: ...

    def mark(self) -> None: ...

    def rewind(self) -> None: ...


class Advance(NamedTuple):
    """What one fresh sample did to the predictors: ``gap``, samples were missed or cycles ran
    without data since the last one seen; ``resync``, the span was redone on the sample clock;
    ``v`` the commanded spool and ``x`` the model position at this sample (m)."""

    gap: bool
    resync: bool
    v: float
    x: float


#: an :class:`Advance`'s fields as a plain tuple (:meth:`SampleClock.tick`)
AdvanceValues = tuple[bool, bool, float, float]


class SampleClock:
    """Valve model, x̂ and (optionally) the pressure model, advanced once per sensor sample."""

    __slots__ = (
        "_bridge_margin",
        "_dead",
        "_match_a",
        "_observed",
        "_wire",
        "echo",
        "pressure",
        "seed",
        "span",
        "valve",
        "xhat",
        "y_seen",
    )

    def __init__(
        self,
        valve: ValvePredictor,
        xhat: ModelPosition,
        pressure: PressureModel | None = None,
        tuning: ControlTuning | None = None,
    ) -> None:
        t = tuning if tuning is not None else ControlTuning()
        self.valve = valve
        self.xhat = xhat
        self.pressure = pressure
        self._match_a = t.wire_match_a  # ControlTuning.wire_match_a (A)
        self._bridge_margin = t.bridge_margin  # ControlTuning.bridge_margin
        self.reset()

    def reset(self) -> None:
        """No sample seen yet (the predictors themselves are reset by their owner)."""
        self._dead = 0
        #: x̂ starts on the first sensor sample after a reset: a reset on leaving the fail-safe
        #: comes mid-motion, and x̂ from 0 put the position channel in guard at once
        self.seed = True
        #: sensor samples the last fresh cycle stood for (when redone on them)
        self.span = 1
        self._observed = 0  # … of the superseded samples observed before it in this cycle
        #: the current commanded in each of the last cycles (A), as held by the valve: a cycle
        #: whose command is not sent repeats the previous one
        self._wire: deque[float] = deque([0.0] * WIRE_COMMANDS, maxlen=WIRE_COMMANDS)
        self.y_seen = 0.0  # the position sensor at the last sample seen (m)
        #: the current echo of the last sample seen (A)
        self.echo = 0.0

    # ---- per cycle --------------------------------------------------------------------------
    def dead_cycle(self, gain: float) -> None:
        """A cycle without data: the predictors step on the command applied over the last sample
        (sent two cycles ago); x̂ integrates ``gain``·v (k̂_LOE: the model spool)."""
        if self._dead == 0:  # the predictors' state at the last sample seen
            self.valve.mark()
            self.xhat.mark()
            if self.pressure is not None:
                self.pressure.mark()
        self._dead += 1
        current = self._wire[-2]
        v = self.valve.step(current)
        self.xhat.integrate(gain * v)
        if self.pressure is not None:
            self.pressure.propagate(current)

    def sample(self, meas: Measurement, gain: float, bridge_gain: float | None) -> Advance:
        """The cycle's own fresh sample: the predictors up to it (see the module). ``gain``:
        k̂_LOE of the model spool; ``bridge_gain``: θ̂_D when the position sensor may place x̂
        across a redone span (None: it may not). Seeds x̂ on the first sample after a reset."""
        return Advance._make(self.tick(meas, gain, bridge_gain))

    def tick(self, meas: Measurement, gain: float, bridge_gain: float | None) -> AdvanceValues:
        """:meth:`sample`'s :class:`Advance` as a plain tuple ``(gap, resync, v, x)``: the mmac
        step unpacks it on every fresh sample (building, then unpacking, a NamedTuple costs
        about 0.1 µs more)."""
        if self._dead == 0 and meas.samples <= 1:
            # the regular sample (no gap, nothing to redo): :meth:`_advance` written out, this
            # runs on every fresh sample
            echo = self.echo = meas.coil_current_a
            adv: AdvanceValues = (False, False, self.valve.step(echo), self.xhat.integrate(meas.spool_m))
            self.y_seen = meas.position_m
        else:
            adv = self._advance(meas, True, gain, bridge_gain)
        self.span, self._observed = self._observed + (meas.samples if adv[1] else 1), 0
        if self.seed:  # the plant is where the sensor says (it is at rest or the sensor is all)
            self.seed = False
            self.xhat.x = meas.position_m
            return (adv[0], adv[1], adv[2], meas.position_m)
        return adv

    def observe(self, meas: Measurement, gain: float) -> Advance:
        """A sample superseded within this cycle: the predictors step on its own spool LVDT and
        current echo, so the cycle's sample is one on from it."""
        adv = self._advance(meas, False, gain, None)
        self._observed += meas.samples if adv.resync else 1
        if self.pressure is not None:
            self.pressure.propagate(meas.coil_current_a)
        return adv

    def commanded(self, current_a: float, sent: bool) -> None:
        """This cycle's command (A, finite), and whether it is sent: one the loop slept through
        never reaches the valve, which keeps the previous one."""
        self._wire.append(current_a if sent else self._wire[-1])

    # ---- internals --------------------------------------------------------------------------
    def _advance(self, meas: Measurement, stepped: bool, gain: float, bridge_gain: float | None) -> Advance:
        dead, self._dead = self._dead, 0
        gap = dead > 0 or meas.samples > 1
        if resync_span(meas.samples, dead):
            v, x = self._predict_span(meas, dead, stepped, gain, bridge_gain)
            out = Advance(gap, True, v, x)
        else:
            self.echo = meas.coil_current_a
            out = Advance(gap, False, self.valve.step(self.echo), self.xhat.integrate(meas.spool_m))
        self.y_seen = meas.position_m
        return out

    def _predict_span(
        self, meas: Measurement, dead: int, stepped: bool, gain: float, bridge_gain: float | None
    ) -> tuple[float, float]:
        """Valve model and x̂ stepped over ``meas.samples`` sensor samples from the last one seen
        (the dead-reckoned steps of the ``dead`` cycles without data undone). Returns (v, x̂) (m)."""
        valve, xh, pm = self.valve, self.xhat, self.pressure
        if dead:
            valve.rewind()
            xh.rewind()
            if pm is not None:
                pm.rewind()
        n, echo_a, y_v = meas.samples, meas.coil_current_a, meas.spool_m
        currents = span_currents(n, dead, self._wire if stepped else None, self.echo, echo_a, self._match_a)
        x0 = xh.x
        e0 = xh.last_spool - gain * valve.v
        vs = []
        for c in currents:
            vs.append(valve.step(c))
            if pm is not None:  # the pressure model too (its update steps this sample)
                pm.propagate(c)
        self.echo = echo_a
        v = valve.step(echo_a)
        en = y_v - gain * v
        for sp in bridge_spool(vs, gain, e0, en):
            xh.integrate(sp)
        x_end = xh.integrate(y_v)
        if n > 1 and not self.seed and bridge_gain is not None:
            u = self._bridge_margin * bridge_bound_m(xh.spool_to_x_m(1.0, n - 1), en - e0)
            dx = (meas.position_m - self.y_seen) / bridge_gain
            xh.x = x0 + min(max(dx, x_end - x0 - u), x_end - x0 + u)
        return v, xh.x


def resync_span(samples: int, dead: int) -> bool:
    """Should the predictors be redone on the sensor's sample clock? Whenever the sensor samples
    since the last one seen differ from one, or cycles without data lie between (``dead``), as
    long as both spans are < 16 (the counter's wrap): a realtime slip, samples superseded within
    one cycle, lost frames, a stall of either process (over which the emulator holds one command:
    the echo that ends it). Longer gaps keep the dead-reckoned state."""
    if samples <= 0 or (samples == 1 and dead == 0):
        return False
    return samples <= RESYNC_SAMPLES and dead < RESYNC_SAMPLES


def span_currents(
    samples: int, dead: int, wire: deque[float] | None, last_echo_a: float, echo_a: float, match_a: float
) -> list[float]:
    """The currents (A) applied over the ``samples − 1`` samples not seen before one whose echo
    is ``echo_a`` (the last one seen had ``last_echo_a``; ``dead`` cycles ran without data in
    between). ``wire``: the commands sent in the cycles before this one (newest last; one sample
    of transport delay, so the echo of this sample is ``wire[-2]``). They are taken when each
    sample not seen had a cycle of its own (``dead == samples − 1``) and this echo confirms the
    valve applied them (within ``match_a``, A: ``ControlTuning.wire_match_a``): the sensor
    frames were lost, the commands got through. Otherwise (fewer cycles than samples: the
    emulator was late; or no ``wire``: a sample superseded within a cycle): the last echo for
    the first period (commanded before that sample) and this echo for the others (a late
    emulator holds the newest command over the periods it skips)."""
    if samples < 2:
        return []
    if wire is not None and dead == samples - 1 and abs(echo_a - wire[-2]) <= match_a:
        return [wire[-m - 2] for m in range(samples - 1, 0, -1)]
    return [last_echo_a] + [echo_a] * (samples - 2)


def bridge_spool(v_m: list[float], gain: float, e_start_m: float, e_end_m: float) -> list[float]:
    """The spool (m) at the samples not seen between two spool LVDT readings: the model's
    ``gain·v`` plus its error ``y_v − gain·v`` at the two readings, interpolated linearly over
    the span (``len(v_m) + 1`` periods). A gain that changed before the span (a k̂_LOE not yet
    converged) leaves the same error at both ends and is removed whole; one that changed inside
    it is split as if at the middle, the expectation over where in the span it changed. With the
    model alone, x̂ was off by (k_LOE − k̂_LOE)·∫v over the span, and the position bank took that
    offset for a drift."""
    n = len(v_m) + 1
    de = (e_end_m - e_start_m) / n
    return [gain * v + e_start_m + de * (j + 1) for j, v in enumerate(v_m)]


def bridge_bound_m(x_per_spool: float, de_m: float) -> float:
    """How far (m) x̂ bridged by :func:`bridge_spool` can be from the truth when the spool error
    changed by ``de_m`` (m) in one step somewhere in the span: the linear interpolation is off
    by at most half the step over the samples not seen; ``x_per_spool`` is x̂'s change per metre
    of spool held over them (m/m)."""
    return 0.5 * x_per_spool * abs(de_m)
