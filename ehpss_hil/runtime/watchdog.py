"""Sensor watchdog (docs/design.md §8): pure logic, one :meth:`SensorWatchdog.update` per cycle.

A cycle is *fresh* when a usable SENSOR_POS frame arrived in it. ``timeout_cycles`` cycles in a
row without one trip the watchdog, with the reason taken from what did arrive meanwhile:
implausible frames → PLAUSIBILITY, frames failing E2E (CRC, sequence, DLC) → E2E_ERRORS, nothing →
SENSOR_TIMEOUT. ``max_e2e_errors`` E2E failures without a usable frame in between trip it too
(E2E_ERRORS). Once tripped it stays tripped until ``recovery_cycles`` fresh cycles in a row have
passed, and then only if ``auto_recover`` is set.

The loop's own time counts too (LOOP_OVERRUN). Grid periods skipped by an overrun
(:meth:`SensorWatchdog.skip`) are cycles without data; more of them at once than
``max_skipped`` (what the predictors can bridge) or ``timeout_cycles`` of them at once is
LOOP_OVERRUN. So is starvation: at least ``starvation_late_fraction`` of the last
``starvation_window_cycles`` grid periods late (the cycle started after its deadline) or skipped;
it does not recover while that holds.
"""

from __future__ import annotations

from ..config import Watchdog
from ..protocol.failsafe import FailsafeReason


class LateWindow:
    """The late-or-skipped grid periods among the last ``window`` (a ring of 0/1 and its sum)."""

    def __init__(self, window: int) -> None:
        self._ring = bytearray(window)
        self._i = 0
        self.late = 0
        self.seen = 0

    def add(self, late: bool, periods: int = 1) -> None:
        """Account ``periods`` grid periods, all late or all on time."""
        ring, n = self._ring, len(self._ring)
        v = int(late)
        for _ in range(min(periods, n)):
            self.late += v - ring[self._i]
            ring[self._i] = v
            self._i = (self._i + 1) % n
        self.seen = min(n, self.seen + periods)

    def fraction(self) -> float:
        """Late share of the full window (0 until the window has been filled once)."""
        n = len(self._ring)
        return self.late / n if self.seen >= n else 0.0


class SensorWatchdog:
    """Counts cycles; ``tripped``/``reason`` say whether the loop must be in fail-safe.

    ``max_skipped``: the most grid periods an overrun may skip at once before the loop must stop
    controlling (the predictors' resynchronization span, ``control.adaptive.RESYNC_SAMPLES``)."""

    def __init__(self, cfg: Watchdog, max_skipped: int = 15) -> None:
        self.cfg = cfg
        self.max_skipped = max_skipped
        self.reset()

    def reset(self) -> None:
        """Healthy, counters cleared."""
        self.tripped = False
        self.reason = FailsafeReason.NONE
        self.stale_cycles = 0
        self.fresh_cycles = 0
        self.e2e_errors = 0
        self._streak_e2e = 0
        self._streak_implausible = 0
        self.trips = 0
        self.overrun_trips = 0
        #: trips per FailsafeReason name (count)
        self.trips_by_reason: dict[str, int] = {}
        #: a fresh cycle came after the last trip (False: no sensor frame since it)
        self.fresh_since_trip = True
        self.lateness = LateWindow(self.cfg.starvation_window_cycles)

    @property
    def starved(self) -> bool:
        """The loop has been late or skipped in too many recent grid periods."""
        return self.lateness.fraction() >= self.cfg.starvation_late_fraction

    def skip(self, periods: int) -> bool:
        """Account ``periods`` grid periods skipped by an overrun: cycles without data (late).
        More than ``max_skipped`` at once, as many as ``timeout_cycles``, or starvation trips
        LOOP_OVERRUN; a timeout reached with executed cycles without data before them trips
        the sensor's reason (:meth:`update`). Returns True when the loop must be in fail-safe."""
        if periods <= 0:
            return self.tripped
        self.lateness.add(True, periods)
        self.stale_cycles += periods
        self.fresh_cycles = 0
        if self.tripped:
            return True
        if periods > self.max_skipped or periods >= self.cfg.timeout_cycles or self.starved:
            self._trip(FailsafeReason.LOOP_OVERRUN)
        else:
            reason = self._trip_reason()
            if reason is not FailsafeReason.NONE:
                self._trip(reason)
        return self.tripped

    def stall(self) -> None:
        """The cycle stalled after reading its data for longer than the window (the process was
        stopped or starved mid-cycle): LOOP_OVERRUN, and recovery needs ``recovery_cycles``
        fresh cycles from now on."""
        self.fresh_cycles = 0
        if not self.tripped:
            self._trip(FailsafeReason.LOOP_OVERRUN)

    def _trip(self, reason: FailsafeReason) -> None:
        self.tripped = True
        self.reason = reason
        self.trips += 1
        self.overrun_trips += reason is FailsafeReason.LOOP_OVERRUN
        self.trips_by_reason[reason.name] = self.trips_by_reason.get(reason.name, 0) + 1
        self.fresh_since_trip = False

    @property
    def silent_since_trip(self) -> bool:
        """Tripped on a sensor timeout and no sensor frame since: at the end of a run, the
        silence after the emulator stopped (not a trip of the run itself)."""
        return self.tripped and self.reason is FailsafeReason.SENSOR_TIMEOUT and not self.fresh_since_trip

    def update(self, fresh: bool, e2e_errors: int = 0, implausible: int = 0, late: bool = False) -> bool:
        """Account one cycle; ``e2e_errors``/``implausible`` = sensor frames rejected this cycle
        for E2E/DLC resp. range reasons; ``late``: it started after its deadline. Returns True
        when the loop must be in fail-safe."""
        self.lateness.add(late)
        if fresh:
            self.stale_cycles = 0
            self.fresh_cycles += 1
            self.fresh_since_trip = True
            self.e2e_errors = 0
            self._streak_e2e = 0
            self._streak_implausible = 0
            if e2e_errors:  # rejected frames next to a good one still count toward the burst
                self.e2e_errors = e2e_errors
        else:
            self.stale_cycles += 1
            self.fresh_cycles = 0
            self.e2e_errors += e2e_errors
            self._streak_e2e += e2e_errors
            self._streak_implausible += implausible
        if not self.tripped:
            reason = self._trip_reason()
            if reason is not FailsafeReason.NONE:
                self._trip(reason)
        elif self.cfg.auto_recover and self.fresh_cycles >= self.cfg.recovery_cycles and not self.starved:
            self.tripped = False
            self.reason = FailsafeReason.NONE
        return self.tripped

    def _trip_reason(self) -> FailsafeReason:
        if self.starved:
            return FailsafeReason.LOOP_OVERRUN
        if self.e2e_errors >= self.cfg.max_e2e_errors:
            return FailsafeReason.E2E_ERRORS
        if self.stale_cycles < self.cfg.timeout_cycles:
            return FailsafeReason.NONE
        if self._streak_implausible:
            return FailsafeReason.PLAUSIBILITY
        if self._streak_e2e:
            return FailsafeReason.E2E_ERRORS
        return FailsafeReason.SENSOR_TIMEOUT
