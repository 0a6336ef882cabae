"""Fixed-grid deadline timer: ``next += period``, sleep to the absolute deadline, never burst.

The sleep is ``time.sleep`` (on Linux with Python ≥ 3.11 it is ``clock_nanosleep`` on
CLOCK_MONOTONIC), never a busy-wait, so it is safe under SCHED_FIFO. When a cycle starts after its
deadline has already passed (the previous cycle overran), the overrun is counted, the grid skips
ahead to the latest grid point not after now (the missed slots are counted as skipped) and the
cycle runs at once: one late cycle, never a burst of catch-up cycles. A warning is logged at most
once a second.
"""

from __future__ import annotations

import logging
import select
import time
from collections.abc import Callable

import can

log = logging.getLogger(__name__)


class DeadlineTimer:
    """Wakes a loop on the grid ``t0 + n·period_s`` (monotonic seconds)."""

    def __init__(
        self,
        period_s: float,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        warn_interval_s: float = 1.0,
        name: str = "loop",
    ) -> None:
        if period_s <= 0.0:
            raise ValueError("period_s must be > 0")
        self.period_s = period_s
        self._clock = clock
        self._sleep = sleep
        self._warn_interval_s = warn_interval_s
        self._name = name
        self._next = 0.0
        self._last_warn = -float("inf")
        self._unwarned = 0
        self.overruns = 0
        self.skipped = 0
        #: grid periods skipped by the last :meth:`wait` (0 when it was on time)
        self.last_skipped = 0
        #: the last :meth:`wait` found its deadline already passed (an overrun)
        self.last_late = False
        self.cycles = 0

    def start(self, now_s: float | None = None) -> None:
        """Put the first deadline one period after ``now_s`` (default: the clock now)."""
        t = self._clock() if now_s is None else now_s
        self._next = t + self.period_s

    @property
    def next_deadline_s(self) -> float:
        """The deadline the next :meth:`wait` sleeps to (monotonic s)."""
        return self._next

    def shift(self, delta_s: float) -> None:
        """Move the next deadline by ``delta_s`` (s): a bounded phase slew (see phaselock)."""
        self._next += delta_s

    def wait(self, wake: Callable[[float], bool] | None = None) -> float:
        """Sleep until the next deadline; returns the wake-up lateness (s, ≥ 0 normally).

        ``wake(timeout_s)``, when given, replaces the sleep: it blocks at most ``timeout_s`` and
        returns True when the cycle should start now (e.g. the sensor frames it waits for have
        arrived); the cycle then starts before its deadline (negative lateness) and the grid
        goes on from that deadline, unchanged."""
        now = self._clock()
        self.last_skipped = 0
        self.last_late = now > self._next
        if self.last_late:
            missed = int((now - self._next) // self.period_s)
            self._next += missed * self.period_s
            self.skipped += missed
            self.last_skipped = missed
            self._overrun(now, missed)
        else:
            while now < self._next:  # sleep may return a little early: sleep again, never spin
                if wake is not None:
                    if wake(self._next - now):
                        now = self._clock()
                        break
                else:
                    self._sleep(self._next - now)
                now = self._clock()
        lateness = now - self._next
        self._next += self.period_s
        self.cycles += 1
        return lateness

    def _overrun(self, now: float, missed: int) -> None:
        self.overruns += 1
        self._unwarned += 1
        if now - self._last_warn >= self._warn_interval_s:
            log.warning(
                "%s: %d overrun(s) since the last warning (this one skipped %d period(s) "
                "of %.3g ms; %d overruns in total)",
                self._name,
                self._unwarned,
                missed,
                self.period_s * 1e3,
                self.overruns,
            )
            self._last_warn = now
            self._unwarned = 0


def socket_wake(bus: can.BusABC, on_readable: Callable[[], bool]) -> Callable[[float], bool] | None:
    """A ``wake`` for :meth:`DeadlineTimer.wait`: block in ``select()`` on the bus socket up to
    the deadline; when it becomes readable, ``on_readable()`` (which drains it) says whether the
    cycle should start now. None (and a warning) when the bus has no file descriptor."""
    try:
        fd = bus.fileno()
    except (NotImplementedError, OSError, AttributeError):
        fd = -1
    if fd < 0:
        log.warning("wake_on_sensor: this bus has no file descriptor; plain deadline grid")
        return None
    fds = (fd,)

    def wake(timeout_s: float) -> bool:
        return bool(select.select(fds, (), (), timeout_s)[0]) and on_readable()

    return wake
