"""Issue #15, in-process: a stalled controller never resumes on stale state. Skipped periods count
for the watchdog, more than the predictors bridge is LOOP_OVERRUN (never stepped blind),
starvation is LOOP_OVERRUN, stale frames are counted and never used, and leaving FAULT restarts
the law bumplessly from the present measurement. Cycles are counted, nothing is timed (the one
sleep below only makes frames older than the window, whatever the host's load)."""

from __future__ import annotations

import time

import pytest
from _daemon_rig import MiniPI, Rig, activate

from ehpss_hil.codec import FrameCodec
from ehpss_hil.config import Watchdog
from ehpss_hil.control.base import Measurement, ValveCommand
from ehpss_hil.control.sampleclock import RESYNC_SAMPLES
from ehpss_hil.protocol.failsafe import FailsafeReason
from ehpss_hil.runtime.lifecycle import State
from ehpss_hil.runtime.watchdog import SensorWatchdog

LONG = Watchdog(timeout_cycles=100, recovery_cycles=5, auto_recover=True)
#: the age window of the stale-frame tests (s): frames a minute old are stale, a cycle is never
#: stalled this long between its drain and its command
STALE_WINDOW_S = 5.0


def _count_steps(rig: Rig) -> list[bool]:
    """Record ``meas.fresh`` of every law step from now on."""
    seen: list[bool] = []
    orig = rig.ctrl.step

    def step(meas: Measurement) -> ValveCommand:
        seen.append(meas.fresh)
        return orig(meas)

    rig.ctrl.step = step  # type: ignore[method-assign]
    return seen


def test_watchdog_counts_skipped_periods() -> None:
    wd = SensorWatchdog(Watchdog(timeout_cycles=5), max_skipped=RESYNC_SAMPLES)
    wd.update(True)
    assert not wd.skip(2) and wd.stale_cycles == 2
    assert not wd.update(False)  # 3 without data
    assert wd.skip(2) and wd.reason is FailsafeReason.SENSOR_TIMEOUT  # 2 skipped after 3 empty
    wd = SensorWatchdog(Watchdog(timeout_cycles=5), max_skipped=RESYNC_SAMPLES)
    assert wd.skip(5) and wd.reason is FailsafeReason.LOOP_OVERRUN  # the loop's own periods
    wd = SensorWatchdog(Watchdog(timeout_cycles=100), max_skipped=RESYNC_SAMPLES)
    assert not wd.skip(RESYNC_SAMPLES)
    wd.update(True)
    assert wd.skip(RESYNC_SAMPLES + 1) and wd.reason is FailsafeReason.LOOP_OVERRUN


def test_starvation_is_a_loop_overrun_and_blocks_recovery() -> None:
    cfg = Watchdog(
        timeout_cycles=10,
        recovery_cycles=5,
        auto_recover=True,
        starvation_window_cycles=100,
        starvation_late_fraction=0.25,
    )
    wd = SensorWatchdog(cfg)
    for k in range(1000):  # every 5th cycle late (20 %): never starved
        assert not wd.update(True, late=k % 5 == 0)
    for _ in range(100):  # every other cycle late, fresh data all along
        if wd.update(True, late=True) or wd.update(True):
            break
    assert wd.tripped and wd.reason is FailsafeReason.LOOP_OVERRUN and wd.overrun_trips == 1
    for _ in range(20):  # fresh but still starved: no recovery
        wd.update(True, late=True)
        wd.update(True)
    assert wd.tripped
    n = 0
    while wd.tripped and n < 1000:  # on time again: recovers once the window has cleared
        wd.update(True)
        n += 1
    assert not wd.tripped and 5 <= n <= 100


@pytest.mark.parametrize("skipped", [RESYNC_SAMPLES + 1, 500, 5000])
def test_more_skipped_periods_than_bridged_is_loop_overrun(skipped: int) -> None:
    r = Rig(f"overrun{skipped}", LONG)
    try:
        activate(r, 20)
        seen = _count_steps(r)
        r.sensors(5e-4)
        r.loop.poll_cycle(skipped=skipped)
        cmd = r.values_of("VALVE_CMD")[-1]
        assert seen == []  # never stepped blind
        assert r.loop.life.state is State.FAULT
        assert r.loop.life.reason is FailsafeReason.LOOP_OVERRUN
        assert cmd["Enable"] == 0 and cmd["CurrentSetpoint"] == 0.0
        assert r.loop.skipped_periods == skipped and r.loop.failsafe_cycles == skipped + 1
    finally:
        r.close()


def test_skipped_periods_within_the_bridge_are_stepped() -> None:
    r = Rig("bridge", LONG)
    try:
        activate(r, 20)
        seen = _count_steps(r)
        r.sensors(5e-4)
        r.loop.poll_cycle(skipped=RESYNC_SAMPLES)
        assert seen == [False] * RESYNC_SAMPLES + [True]
        assert r.loop.life.state is State.ACTIVE
    finally:
        r.close()


def test_skipped_periods_reach_the_timeout() -> None:
    """The shipped 3-cycle watchdog: an overrun of 3 periods is a LOOP_OVERRUN."""
    r = Rig("timeout3", Watchdog(timeout_cycles=3))
    try:
        activate(r, 20)
        seen = _count_steps(r)
        r.sensors(5e-4)
        r.loop.poll_cycle(skipped=3)
        assert seen == [] and r.loop.life.reason is FailsafeReason.LOOP_OVERRUN
    finally:
        r.close()


def test_stale_frames_are_counted_not_used() -> None:
    """Frames received longer ago than the window are classified and counted, never used: the
    position is not taken, the cycle is one without data (echo 0); a fresh frame after them is
    used. (virtual: a frame's timestamp is what its sender set; the stale ones are a minute
    old against a 5-s window, so no host load changes which frames are stale.)"""
    r = Rig("stale", Watchdog(timeout_cycles=3))
    try:
        activate(r, 20)
        r.sensors(1e-4)
        r.cycle()
        r.loop.check_age, r.loop.stale_after_s = True, STALE_WINDOW_S
        for _ in range(3):
            r.old_sensors(9e-3, age_s=60.0)
        cmd = r.cycle()["VALVE_CMD"]
        assert r.loop.stale_frames == 6 and r.loop.meas.position_m == pytest.approx(1e-4)
        assert cmd["SensorCounterEcho"] == 0 and r.loop.wd.stale_cycles == 1
        assert cmd["Enable"] == 1
        fresh = r.sensors(2e-4)
        cmd = r.cycle()["VALVE_CMD"]
        assert cmd["SensorCounterEcho"] == fresh.data[1] & 0x0F
        assert r.loop.meas.position_m == pytest.approx(2e-4)
    finally:
        r.close()


def test_stale_frames_lead_to_sensor_timeout() -> None:
    r = Rig("stale-timeout", Watchdog(timeout_cycles=3))
    try:
        activate(r, 20)
        r.loop.check_age, r.loop.stale_after_s = True, STALE_WINDOW_S
        for _ in range(3):
            r.old_sensors(9e-3, age_s=60.0)
            r.cycle()
        assert r.loop.life.state is State.FAULT
        assert r.loop.life.reason is FailsafeReason.SENSOR_TIMEOUT
    finally:
        r.close()


def test_leaving_fault_restarts_the_law_from_the_present_measurement() -> None:
    """After a LOOP_OVERRUN and recovery the first command is what a freshly started law gives
    on the present measurement and reference: no wound-up integrator, no stale state."""
    r = Rig("bumpless", LONG)
    try:
        activate(r, 200)  # integrator wound up on a 1 mm error
        r.sensors(0.0)
        r.loop.poll_cycle(skipped=100)
        assert r.loop.life.reason is FailsafeReason.LOOP_OVERRUN
        n = 0
        while (cmd := r.cycle_with(3e-4))["Enable"] == 0 and n < 1000:
            n += 1
        # the starvation window (200 periods, 100 late) clears first, then 5 fresh cycles
        assert r.loop.life.state is State.ACTIVE and n >= LONG.recovery_cycles
        fresh = MiniPI()
        expect = fresh.step(Measurement(position_m=3e-4, reference_m=1e-3)).current_a
        q = FrameCodec().quantize("VALVE_CMD", {"CurrentSetpoint": expect})["CurrentSetpoint"]
        assert cmd["CurrentSetpoint"] == pytest.approx(q, abs=1e-6)
    finally:
        r.close()


def test_a_cycle_stalled_after_its_drain_sends_the_failsafe_command() -> None:
    """The process stopped between reading its frames and sending its command (a SIGSTOP or a
    starved host mid-cycle) for longer than the window: the command computed on those frames is
    not sent; the watchdog trips LOOP_OVERRUN, 0 A with Enable 0 goes out, and recovery needs
    ``recovery_cycles`` fresh cycles. The frames were fresh when read (no age check then); the
    stall is made real with a sleep longer than the window set afterwards."""
    r = Rig("stall-mid-cycle", LONG)
    try:
        activate(r, 20)
        r.sensors(5e-4)
        r.loop.drain()
        assert r.loop.stale_frames == 0
        r.loop.check_age, r.loop.stale_after_s = True, 1e-3
        time.sleep(0.005)
        r.loop.cycle()
        cmd = r.values_of("VALVE_CMD")[-1]
        assert cmd["Enable"] == 0 and cmd["CurrentSetpoint"] == 0.0
        assert r.loop.life.state is State.FAULT
        assert r.loop.life.reason is FailsafeReason.LOOP_OVERRUN and r.loop.wd.overrun_trips == 1
        r.loop.stale_after_s = 1e9  # on time again
        enabled = [r.cycle_with(5e-4)["Enable"] for _ in range(LONG.recovery_cycles + 1)]
        assert enabled[: LONG.recovery_cycles - 1] == [0] * (LONG.recovery_cycles - 1)
        assert enabled[-1] == 1
    finally:
        r.close()
