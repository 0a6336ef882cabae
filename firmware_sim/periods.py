"""The emulator's real-time period loop, shared by the native and the CANopen processes."""

from __future__ import annotations

import time
from collections.abc import Callable

from ehpss_hil.runtime.deadline import DeadlineTimer
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.runtime.stats import LoopStats


def run_periods(
    ts_s: float,
    step_period: Callable[[int], object],
    periods: Callable[[], int],
    stats: LoopStats,
    stop: StopFlag,
    n_periods: int | None = None,
) -> None:
    """Call ``step_period(skipped)`` once per period of ``ts_s`` (s) on the deadline grid until
    ``stop`` or ``periods() == n_periods``; ``skipped``: the periods the host slept through
    before this one (never past ``n_periods``). Compute time and lateness go into ``stats``,
    and the timer's overrun and skip counts at the end."""
    timer = DeadlineTimer(ts_s, name="firmware-sim")
    timer.start()
    perf = time.perf_counter
    while not stop and (n_periods is None or periods() < n_periods):
        lateness = timer.wait()
        t0 = perf()
        skipped = timer.last_skipped
        if n_periods is not None:
            skipped = min(skipped, max(0, n_periods - periods() - 1))
        step_period(skipped)
        stats.compute.add(perf() - t0)
        stats.lateness.add(lateness)
    stats.overruns = timer.overruns
    stats.skipped = timer.skipped
