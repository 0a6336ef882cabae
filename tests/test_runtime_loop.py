"""Deadline grid (fake clock: no wall-clock timing), loop statistics, RT options."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from ehpss_hil.config import RtOptions
from ehpss_hil.runtime import rt
from ehpss_hil.runtime.deadline import DeadlineTimer
from ehpss_hil.runtime.stats import LoopStats, Ring


class FakeClock:
    """Monotonic seconds that only move when the loop sleeps or 'computes'."""

    def __init__(self) -> None:
        self.t = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        assert dt > 0.0  # never a zero/negative sleep, never a spin
        self.sleeps.append(dt)
        self.t += dt


def _timer(clock: FakeClock, period: float = 1e-3) -> DeadlineTimer:
    t = DeadlineTimer(period, clock=clock, sleep=clock.sleep)
    t.start()
    return t


def test_fixed_grid_sleeps_to_absolute_deadlines() -> None:
    clock = FakeClock()
    t = _timer(clock)
    t0 = clock.t
    for n in range(1, 6):
        clock.t += 0.0002  # compute 0.2 ms
        assert t.wait() == 0.0
        assert clock.t == pytest.approx(t0 + n * 1e-3)  # on the grid, no drift
    assert t.overruns == 0
    assert clock.sleeps == pytest.approx([0.8e-3] * 5)


def test_overrun_counted_skips_ahead_never_bursts() -> None:
    clock = FakeClock()
    t = _timer(clock)
    t0 = clock.t
    t.wait()  # cycle 1 at t0 + 1 ms
    clock.t += 3.5e-3  # this cycle overruns by 2.5 periods
    lateness = t.wait()  # runs at once, on the latest grid point (t0 + 4 ms)
    assert t.overruns == 1 and t.skipped == 2
    assert lateness == pytest.approx(0.5e-3)
    n_sleeps = len(clock.sleeps)
    t.wait()  # the next one sleeps to t0 + 5 ms: no catch-up burst
    assert len(clock.sleeps) == n_sleeps + 1
    assert clock.t == pytest.approx(t0 + 5e-3)


def test_overrun_warning_at_most_once_a_second(caplog: pytest.LogCaptureFixture) -> None:
    clock = FakeClock()
    t = _timer(clock)
    with caplog.at_level(logging.WARNING, logger="ehpss_hil.runtime.deadline"):
        for _ in range(3000):  # 3000 overrunning cycles of 1.5 ms = 4.5 s
            t.wait()
            clock.t += 1.5e-3
    assert t.overruns >= 2999
    assert 4 <= len(caplog.records) <= 6


def test_ring_percentiles_and_wraparound() -> None:
    r = Ring(1000)
    for v in np.arange(2000, dtype=float):
        r.add(v)
    s = r.summary()
    assert s["n"] == 2000 and s["max"] == 1999.0
    assert s["p50"] == pytest.approx(np.percentile(np.arange(1000, 2000), 50))
    assert s["p99"] == pytest.approx(np.percentile(np.arange(1000, 2000), 99))


def test_loop_stats_summary_text() -> None:
    st = LoopStats(100)
    for i in range(10):
        st.compute.add(i * 1e-6)
        st.lateness.add(2e-6)
    st.overruns = 3
    s = st.summary()
    assert s["overruns"] == 3 and s["latency_s"]["n"] == 0
    assert "p99" in st.text() and "overruns=3" in st.text()


def test_rt_options_warn_instead_of_failing(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*a: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(rt.os, "sched_setscheduler", refuse)
    monkeypatch.setattr(rt.os, "sched_setaffinity", refuse)
    w = rt.apply_rt_options(RtOptions(priority=50, cpu=0))
    assert any("SCHED_FIFO" in x for x in w) and any("affinity" in x for x in w)


def test_rt_cpu_and_timer_slack_apply() -> None:
    """The CPU pin covers the threads already running (the log writer starts before the RT
    options are applied) as well as the calling one."""
    import os
    import threading

    before = os.sched_getaffinity(0)
    cpu = min(before)
    started, release = threading.Event(), threading.Event()

    def writer() -> None:
        started.set()
        release.wait(10.0)

    t = threading.Thread(target=writer, daemon=True)
    t.start()
    started.wait(10.0)
    try:
        assert rt.set_cpu(cpu) is None
        assert os.sched_getaffinity(0) == {cpu}
        assert t.native_id is not None and os.sched_getaffinity(t.native_id) == {cpu}
    finally:
        release.set()
        t.join()
        for tid in os.listdir("/proc/self/task"):
            try:
                os.sched_setaffinity(int(tid), before)
            except ProcessLookupError:
                pass
    assert rt.set_timer_slack(50_000) is None


def test_phase_lock_converges_to_target_age() -> None:
    """Sensor frames arrive every T at phase 0.37 T; the slewed grid settles with the frame's age
    at the deadline equal to the target (pure arithmetic: no clock)."""
    from ehpss_hil.runtime.phaselock import PhaseLock

    period, phase, target = 1e-3, 0.37e-3, 150e-6
    lock = PhaseLock(period, target)
    deadline = 0.9e-3  # arbitrary start phase
    ages = []
    for n in range(2000):
        if n == 1:  # after the one-off alignment at the first frame, jump the sensor's phase
            phase += 0.41e-3
        arrival = np.floor((deadline - phase) / period) * period + phase  # newest frame so far
        shift = lock.correction(deadline, arrival)
        if n == 0:  # the first frame aligns the grid at once
            assert (deadline + shift) - arrival == pytest.approx(target, abs=1e-12)
        else:
            assert abs(shift) <= lock.max_slew_s  # then bounded slew: the grid never jumps
        deadline += period + shift
        ages.append(lock.last_age_s)
    assert ages[1] != pytest.approx(target, abs=1e-5)  # the phase jump shows ...
    assert lock.last_age_s == pytest.approx(target, abs=1e-6)  # ... and is slewed out


def test_phase_lock_wraps_a_just_missed_frame() -> None:
    from ehpss_hil.runtime.phaselock import PhaseLock

    lock = PhaseLock(1e-3, 150e-6)
    lock.locked = True  # past the first frame's alignment
    assert lock.error(0.99e-3) == pytest.approx(-0.16e-3)  # just missed: pull back, not +T
    assert lock.correction(1.0, 1.0 - 0.99e-3) == pytest.approx(16e-6)  # later, bounded


def test_wake_starts_the_cycle_early_and_keeps_the_grid() -> None:
    """``wait(wake)``: the wake callback blocks instead of sleep; when it reports the awaited
    frames (here 0.3 ms into a period) the cycle starts early (negative lateness), when it
    times out the cycle starts at the deadline; either way the grid is unchanged."""
    clock = FakeClock()
    t = _timer(clock)
    t0 = clock.t
    timeouts: list[float] = []

    def frames_at(offset_s: float | None):  # type: ignore[no-untyped-def]
        def wake(timeout_s: float) -> bool:
            timeouts.append(timeout_s)
            assert timeout_s > 0.0
            period_start = t.next_deadline_s - 1e-3
            if offset_s is not None and period_start + offset_s < clock.t + timeout_s:
                clock.t = max(clock.t, period_start + offset_s)
                return True
            clock.t += timeout_s
            return False

        return wake

    assert t.wait(frames_at(0.3e-3)) == pytest.approx(-0.7e-3)  # 0.3 ms into period 1
    assert clock.t == pytest.approx(t0 + 0.3e-3)
    assert t.wait(frames_at(None)) == 0.0  # nothing came: at the deadline t0 + 2 ms
    assert clock.t == pytest.approx(t0 + 2e-3)
    assert t.wait(frames_at(0.5e-3)) == pytest.approx(-0.5e-3)  # grid unchanged: 2 ms + 0.5
    assert clock.t == pytest.approx(t0 + 2.5e-3)
    assert t.overruns == 0 and t.cycles == 3 and clock.sleeps == []
