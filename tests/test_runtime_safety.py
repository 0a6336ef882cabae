"""Watchdog (cycles counted), lifecycle transitions, SIGTERM → stop flag."""

from __future__ import annotations

import os
import signal

import pytest

from ehpss_hil.config import Watchdog
from ehpss_hil.protocol.failsafe import FailsafeReason
from ehpss_hil.runtime.lifecycle import Lifecycle, LifecycleError, State
from ehpss_hil.runtime.signals import install_stop_handlers, restore_handlers
from ehpss_hil.runtime.watchdog import SensorWatchdog


def _cycles_to_trip(wd: SensorWatchdog, e2e_errors: int = 0, implausible: int = 0) -> int:
    for n in range(1, 100):
        if wd.update(False, e2e_errors=e2e_errors, implausible=implausible):
            return n
    return -1


def test_trips_after_timeout_cycles_with_reason() -> None:
    cfg = Watchdog(timeout_cycles=3)
    wd = SensorWatchdog(cfg)
    for _ in range(10):
        assert not wd.update(True)
    assert _cycles_to_trip(wd) == 3 and wd.reason is FailsafeReason.SENSOR_TIMEOUT
    wd = SensorWatchdog(cfg)
    assert _cycles_to_trip(wd, e2e_errors=1) == 3 and wd.reason is FailsafeReason.E2E_ERRORS
    wd = SensorWatchdog(cfg)
    assert _cycles_to_trip(wd, implausible=1) == 3 and wd.reason is FailsafeReason.PLAUSIBILITY


def test_e2e_burst_trips_early() -> None:
    wd = SensorWatchdog(Watchdog(timeout_cycles=100, max_e2e_errors=10))
    assert not wd.update(False, e2e_errors=4)
    assert wd.update(False, e2e_errors=6) and wd.reason is FailsafeReason.E2E_ERRORS


def test_no_recovery_unless_allowed() -> None:
    wd = SensorWatchdog(Watchdog(timeout_cycles=3, recovery_cycles=5, auto_recover=False))
    _cycles_to_trip(wd)
    for _ in range(100):
        assert wd.update(True)


def test_recovery_after_m_fresh_cycles() -> None:
    wd = SensorWatchdog(Watchdog(timeout_cycles=3, recovery_cycles=5, auto_recover=True))
    _cycles_to_trip(wd)
    for _ in range(4):
        assert wd.update(True)
    assert wd.update(False)  # still tripped; a stale cycle restarts the count
    results = [wd.update(True) for _ in range(5)]
    assert results == [True, True, True, True, False]
    assert wd.reason is FailsafeReason.NONE


def test_lifecycle_numbers_and_transitions() -> None:
    assert [int(s) for s in State] == [0, 1, 2, 3, 4]  # DBC CTRL_STATUS State VAL_
    lc = Lifecycle()
    with pytest.raises(LifecycleError):
        lc.to(State.ACTIVE)
    lc.to(State.CONFIGURED)
    lc.to(State.ACTIVE)
    lc.to(State.FAULT, FailsafeReason.SENSOR_TIMEOUT)
    assert lc.reason is FailsafeReason.SENSOR_TIMEOUT and lc.nmt_state == 127
    lc.to(State.ACTIVE)
    assert lc.reason is FailsafeReason.NONE and lc.nmt_state == 5
    lc.to(State.STOPPED)
    with pytest.raises(LifecycleError):
        lc.to(State.ACTIVE)


def test_sigterm_sets_stop_flag() -> None:
    flag, previous = install_stop_handlers()
    try:
        assert not flag
        os.kill(os.getpid(), signal.SIGTERM)
        assert flag and flag.signum == signal.SIGTERM
    finally:
        restore_handlers(previous)
