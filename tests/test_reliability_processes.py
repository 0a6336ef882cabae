"""Reliability with real processes on the embedded bus, each trial in its own private network
namespace beside a bus logger: kill -9 of either process, SIGTERM during a run, duplicated /
reordered / burst sensor frames against a controller process, bad configs and scenarios.
Nothing here is timed: waits have generous limits only so that a broken run fails."""

from __future__ import annotations

import random
import warnings
from pathlib import Path

import pytest

from ehpss_hil.reliability.badinput import Mutation, mutations, run_bad_inputs
from ehpss_hil.reliability.duplicates import dup_trial
from ehpss_hil.reliability.kills import configured_limits, kill_trial, term_trial
from ehpss_hil.reliability.procs import skip_reason

SKIP = skip_reason()
pytestmark = pytest.mark.skipif(SKIP is not None, reason=str(SKIP))


@pytest.mark.alone  # counts the survivor's cycles to its safe state and audits its watchdog
@pytest.mark.parametrize("victim", ["emulator", "controller"])
def test_kill9_survivor_reaches_safe_state_and_keeps_a_complete_log(tmp_path: Path, victim: str) -> None:
    r = kill_trial(tmp_path, 0, victim, random.Random(7 if victim == "emulator" else 8))
    assert not r.error, r.error
    limits = configured_limits()
    if victim == "emulator":  # the controller: 0 A, Enable 0 after timeout_cycles stale cycles
        assert r.limit == limits["controller"]
        assert r.safe is not None and r.safe <= r.limit  # (< only if a host stall tripped it)
        assert r.audit is not None and r.audit.spurious == r.audit.missed == 0
        assert r.status is not None and r.status[0] == "FAULT"
    else:  # the emulator: CmdTimeout after 10 periods, 0 A applied from then on
        assert r.safe == limits["emulator"] == r.limit
        assert r.zero_current is not None and r.zero_current <= r.limit
    assert r.survivor_exit == 0
    lg = r.log
    assert lg.frames > 100 and lg.bad_lines == 0 and lg.complete
    assert (lg.rx_missing, lg.rx_extra, lg.tx_missing, lg.tx_extra) == (0, 0, 0, 0)
    assert r.ok


def test_sigterm_zero_current_exit_0_and_flushed_logs(tmp_path: Path) -> None:
    r = term_trial(tmp_path, 0, "controller", random.Random(3))
    assert not r.error, r.error
    assert r.exits == {"controller": 0, "emulator": 0}
    assert r.last_command == (0.0, 0) and r.command_delivered
    for p in ("controller", "emulator"):
        a = r.logs[p]
        assert a.frames > 100 and a.bad_lines == 0 and a.complete
        assert a.rx_missing == a.tx_missing == a.rx_extra == a.tx_extra == 0
        assert r.closed[p] and r.dropped[p] == 0
    assert r.ok


@pytest.mark.alone
def test_duplicates_reordering_bursts_counted_and_never_acted_on_twice(tmp_path: Path) -> None:
    r = dup_trial(tmp_path, samples=500, seed=4)
    assert not r.error, r.error
    for v in ("OK", "OK_SOME_LOST", "REPEATED", "WRONG_SEQUENCE"):
        assert r.counted[v] == r.expected[v], v
    assert r.expected["REPEATED"] > 0 and r.expected["WRONG_SEQUENCE"] > 0
    assert r.frames_missing == r.frames_extra == 0
    assert r.acted_twice == r.acted_on_late == r.wrong_sample == 0
    assert r.controller_exit == 0
    assert r.acted > 0
    if r.failsafe_cycles:  # a starved host tripped the watchdog: those cycles act on nothing
        warnings.warn(
            f"the controller spent {r.failsafe_cycles} cycles in its fail-safe (a loaded host): "
            f"acted on {r.acted} of {r.distinct_usable} distinct samples, not judged",
            stacklevel=1,
        )
    else:
        assert r.acted > 100 and r.acted == r.distinct_usable


def test_bad_configs_and_scenarios_exit_2_naming_the_key_and_stay_off_the_bus(tmp_path: Path) -> None:
    wanted = {
        ("controller", "watchdog.timeout_cycles"),
        ("controller", "bus.channel"),
        ("controller", "mode"),
        ("controller", "log.path"),
        ("controller", "dbc"),
        ("emulator", "command_timeout_s"),
        ("emulator", "scenario"),
        ("emulator", "truth"),
        ("scenario", "events[1].k_loe"),
        ("scenario", "sensor_frame_loss"),
        ("scenario", "events[3].command_frame_loss"),
        ("scenario", "typo_key"),
    }
    muts = [m for m in mutations(tmp_path) if (m.target, m.key_path) in wanted]
    muts = [m for m in muts if m.why != "type" or m.key_path in ("truth", "typo_key")]
    assert {(m.target, m.key_path) for m in muts} == wanted
    results, frames = run_bad_inputs(tmp_path, muts)
    for r in results:
        assert r.exit_code == 2 and len(r.lines) == 1 and r.names_key, (r.mutation, r.lines)
    assert frames == 0


def test_a_valid_config_does_reach_the_bus(tmp_path: Path) -> None:
    """The control for the test above: the same harness sees frames when a process runs."""
    (result,), frames = run_bad_inputs(tmp_path, [Mutation("controller", ("rate_hz",), 500.0, "valid")])
    assert result.exit_code == 0 and not result.ok
    assert frames > 0
