"""The one controller driver: sensor values in, one command per cycle out.

The daemon's loop, ``replay``, the lockstep simulator and the sample logs all run a controller the
same way, and this class is that way:

* the frames of a cycle are offered as they arrive, classified by the codec
  (:meth:`ControllerDriver.take`: the one mapping of decoded SENSOR_POS, SENSOR_AUX and SETPOINT
  frames onto :meth:`ControllerDriver.position`, :meth:`ControllerDriver.aux` and
  :meth:`ControllerDriver.setpoint`); a SENSOR_POS superseded by a newer one in the same cycle is kept
  and handed to the controller's ``observe`` before the cycle's step, so its predictors stay on
  the sensor's sample clock; the samples between those stepped on come from the SENSOR_POS E2E
  counter (``Measurement.samples``);
* :meth:`ControllerDriver.catch_up` steps the periods a loop slept through without data and
  without a command sent (the valve holds the previous one), at most :data:`RESYNC_SAMPLES`;
* :meth:`ControllerDriver.step` is the cycle's step: x_d at the cycle's reference sample (or the
  SETPOINT override), the controller's command clipped to ±``current_limit_a`` (a non-finite one
  is 0 A) and counted when clipped;
* :meth:`ControllerDriver.failsafe_cycle` is a cycle the controller does not run (the reference
  runs on), :meth:`ControllerDriver.restart` the reset on leaving the fail-safe.

What a cycle *is* — a deadline, a received frame pair, a logged VALVE_CMD, a simulated sample —
and when the controller is in fail-safe are the caller's business.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from .codec import Decoded, SampleCount
from .control.base import Controller, HeldSample, Measurement, hold_sample, observe_held
from .control.sampleclock import RESYNC_SAMPLES

#: the largest number of periods :meth:`ControllerDriver.catch_up` steps without data
MAX_CATCH_UP = RESYNC_SAMPLES

#: a SETPOINT policy: ``admit(override, position_m, x_d_m)`` → the SETPOINT takes effect
#: (``x_d_m``: the x_d in force, m; :meth:`ehpss_hil.runtime.foreign.SetpointGate.admit`)
SetpointAdmit = Callable[[bool, float, float], bool]


class ControllerDriver:
    """Runs one controller one cycle at a time; ``reference(k)`` gives x_d at sample k (m)."""

    __slots__ = (
        "_counter",
        "_fresh",
        "_held",
        "_observe",
        "_samples",
        "_scratch",
        "caught_up",
        "controller",
        "current_limit_a",
        "k",
        "meas",
        "override_m",
        "reference",
        "saturations",
    )

    def __init__(
        self, controller: Controller, reference: Callable[[int], float], current_limit_a: float = 1.0
    ) -> None:
        self.controller = controller
        self.reference = reference
        self.current_limit_a = current_limit_a
        #: the reference sample of the next cycle (cycles stepped, caught up or in fail-safe)
        self.k = 0
        #: commands clipped to ±current_limit_a or non-finite
        self.saturations = 0
        #: periods stepped by :meth:`catch_up`
        self.caught_up = 0
        self.meas = Measurement()
        self.override_m: float | None = None
        self._observe: Callable[[Measurement], None] | None = getattr(controller, "observe", None)
        self._samples = SampleCount()
        self._held: list[HeldSample] = []
        self._scratch = Measurement()
        self._fresh = False
        self._counter = 0

    # ---- the frames of a cycle --------------------------------------------------------------
    def take(self, d: Decoded, admit: SetpointAdmit | None = None) -> None:
        """One usable classified frame (``d.values`` set) onto the driver: the one mapping of
        decoded frames onto it, for the daemon's loop, replay, the sample logs and the
        simulator's frame transports. SENSOR_POS → :meth:`position` (Position, Spool, and the
        E2E counter the codec decoded, ``d.counter``); SENSOR_AUX → :meth:`aux` (CoilCurrent,
        LoadPressure); SETPOINT → :meth:`setpoint` (Position with Override 1, else None) when
        ``admit(override, position_m, x_d in force)`` says so (None: SETPOINT ignored). Other
        frames, and frames without values, are ignored."""
        v = d.values
        if v is None:
            return
        name = d.name
        if name == "SENSOR_POS":
            self.position(float(v["Position"]), float(v["Spool"]), d.counter or 0)
        elif name == "SENSOR_AUX":
            self.aux(float(v["CoilCurrent"]), float(v["LoadPressure"]))
        elif name == "SETPOINT" and admit is not None:
            override, position_m = bool(v["Override"]), float(v["Position"])
            if admit(override, position_m, self._x_d()):
                self.setpoint(position_m if override else None)

    def position(self, position_m: float, spool_m: float, counter: int) -> None:
        """A usable SENSOR_POS (m, m; ``counter`` its E2E counter); a newer one in the same cycle
        supersedes it (kept for ``observe``)."""
        m = self.meas
        if self._fresh and self._observe is not None:
            self._held.append(hold_sample(m, self._counter))
        m.position_m, m.spool_m = position_m, spool_m
        self._fresh = True
        self._counter = counter

    def aux(self, coil_current_a: float, load_pressure_pa: float) -> None:
        """A usable SENSOR_AUX: the current echo (A) and the load pressure (Pa)."""
        self.meas.coil_current_a = coil_current_a
        self.meas.load_pressure_pa = load_pressure_pa

    def sensors(
        self, position_m: float, spool_m: float, counter: int, coil_current_a: float, load_pressure_pa: float
    ) -> None:
        """A usable SENSOR_POS and SENSOR_AUX of one sample in one call: :meth:`position` then
        :meth:`aux`, written out (the simulator's quantize transport hands both every sample)."""
        m = self.meas
        if self._fresh and self._observe is not None:
            self._held.append(hold_sample(m, self._counter))
        m.position_m, m.spool_m = position_m, spool_m
        m.coil_current_a, m.load_pressure_pa = coil_current_a, load_pressure_pa
        self._fresh = True
        self._counter = counter

    def setpoint(self, override_m: float | None) -> None:
        """A SETPOINT override of x_d (m), or None to follow the reference again."""
        self.override_m = override_m

    @property
    def fresh(self) -> bool:
        """A SENSOR_POS arrived in this cycle."""
        return self._fresh

    @property
    def counter(self) -> int:
        """The E2E counter of the newest SENSOR_POS (VALVE_CMD's SensorCounterEcho)."""
        return self._counter

    def _x_d(self) -> float:
        return self.override_m if self.override_m is not None else self.reference(self.k)

    # ---- cycles -----------------------------------------------------------------------------
    def catch_up(self, periods: int) -> int:
        """Periods slept through, before this cycle's frames: each a step without data
        (``fresh`` False, the predictors advance, the reference moves on) and without a command
        sent (``command_sent`` False: the valve keeps the previous one). At most
        :data:`MAX_CATCH_UP` are stepped; the rest only move the reference on. Returns the
        periods stepped."""
        if periods <= 0:
            return 0
        n = min(periods, MAX_CATCH_UP)
        m = self.meas
        fresh = m.fresh
        m.fresh = m.command_sent = False
        for _ in range(n):
            m.reference_m = self._x_d()
            self.controller.step(m)
            self.k += 1
        m.fresh, m.command_sent = fresh, True
        self.k += periods - n
        self.caught_up += n
        return n

    def step(self) -> tuple[float, bool]:
        """The cycle's step: held samples observed, then the controller on the newest values.
        Returns (current (A), enable), the current clipped to ±``current_limit_a``."""
        m = self.meas
        if self._held and self._observe is not None:
            observe_held(self._observe, self._held, self._samples.take, self._scratch)
        ov = self.override_m  # :meth:`_x_d` written out: this runs every cycle
        m.reference_m = ov if ov is not None else self.reference(self.k)
        fresh = m.fresh = self._fresh
        if fresh:
            m.samples = self._samples.take(self._counter)
        cmd = self.controller.step(m)
        self.k += 1
        self._fresh = False
        cur, lim = cmd.current_a, self.current_limit_a
        # not finite, or beyond ±lim, tested without calls (every cycle): NaN fails the range,
        # an infinite current leaves a NaN difference also when the limit is infinite
        if not -lim <= cur <= lim or cur - cur != 0.0:
            self.saturations += 1
            cur = 0.0 if not math.isfinite(cur) else max(-lim, min(lim, cur))
        return cur, cmd.enable

    def failsafe_cycle(self, periods: int = 1) -> None:
        """Cycles the controller does not run (fail-safe): the reference runs on, the frames of
        the cycle are dropped."""
        self.k += periods
        self._fresh = False
        self._held.clear()

    def idle_cycle(self) -> None:
        """A cycle before the controller starts (no reference sample used)."""
        self._fresh = False
        self._held.clear()

    def restart(self) -> None:
        """Leaving the fail-safe: the controller starts afresh on the next measurement."""
        self.controller.reset()
        self._samples.reset()
