"""The realtime verdict (``runtime/rtverdict.py``) on exit summaries as the two processes write
them: thresholds crossed or not → valid, and one reason per threshold crossed; the watchdog
counters it reads; which scenarios lose frames on purpose; the demo's verdict over its runs."""

from __future__ import annotations

import copy
from dataclasses import fields
from typing import Any

from ehpss_hil import PROJECT_ROOT as ROOT
from ehpss_hil.config import Watchdog
from ehpss_hil.run_metrics import loses_frames
from ehpss_hil.runtime.rtverdict import LOCKSTEP_REASON, RealtimeThresholds, combine, judge
from ehpss_hil.runtime.watchdog import SensorWatchdog
from ehpss_hil.scenario import load_scenario

T_S = 1e-3


def _ring(p99_s: float) -> dict[str, float]:
    return {"n": 4500, "p50": 3e-5, "p99": p99_s, "p99_9": 2 * p99_s, "max": 3 * p99_s}


#: a controller-summary.json of a clean 4.5-s run (the fields the verdict reads, as written by
#: runtime/loop_run.loop_summary), ended by the emulator stopping first
CONTROLLER: dict[str, Any] = {
    "cycles": 4600,
    "skipped_periods": 2,
    "state": "STOPPED",
    "failsafe_reason": "SENSOR_TIMEOUT",
    "watchdog_trips": 1,
    "watchdog_trips_by_reason": {"SENSOR_TIMEOUT": 1},
    "watchdog_trip_at_end": True,
    "failsafe_cycles": 90,
    "stats": {
        "compute_s": _ring(2.7e-4),
        "lateness_s": _ring(1.2e-4),
        "latency_s": _ring(4.8e-4),
        "overruns": 3,
        "skipped": 2,
    },
}
#: an emulator-summary.json of the same run
EMULATOR: dict[str, Any] = {
    "periods": 4500,
    "skipped_periods": 1,
    "commands_accepted": 4490,
    "stats": {"compute_s": _ring(4e-4), "lateness_s": _ring(9e-5), "overruns": 1, "skipped": 1},
}


def _with(base: dict[str, Any], **changes: Any) -> dict[str, Any]:
    d = copy.deepcopy(base)
    for dotted, v in changes.items():
        node = d
        *parents, leaf = dotted.split("__")
        for p in parents:
            node = node[p]
        node[leaf] = v
    return d


def test_a_clean_run_is_valid_and_the_trip_at_its_end_is_not_a_reason() -> None:
    v = judge(CONTROLLER, EMULATOR, T_S, steal_fraction=0.01)
    assert v.valid and v.reasons == []
    assert v.line() == "realtime: valid"
    assert v.to_json() == {"realtime_valid": True, "realtime_reasons": []}


def test_a_sensor_timeout_in_mid_run_is_a_reason_unless_the_scenario_loses_frames() -> None:
    ctl = _with(CONTROLLER, watchdog_trips=2, watchdog_trips_by_reason={"SENSOR_TIMEOUT": 2})
    v = judge(ctl, EMULATOR, T_S)
    assert not v.valid
    assert v.reasons == [
        "controller watchdog tripped 1× on late sensor frames (SENSOR_TIMEOUT; the scenario "
        "loses none; limit 0)"
    ]
    assert judge(ctl, EMULATOR, T_S, frame_loss=True).valid
    # the same single trip, but sensor frames came after it: it was not the end of the run
    mid = _with(CONTROLLER, watchdog_trip_at_end=False)
    assert not judge(mid, EMULATOR, T_S).valid


def test_a_starved_run_names_every_threshold_it_crossed() -> None:
    """The counters of a run beside stress-ng: a LOOP_OVERRUN fail-safe, 399 skipped periods,
    late wake-ups in both processes, steal."""
    ctl = _with(
        CONTROLLER,
        skipped_periods=399,
        watchdog_trips=2,
        watchdog_trips_by_reason={"LOOP_OVERRUN": 1, "SENSOR_TIMEOUT": 1},
        stats__lateness_s=_ring(2.1e-3),
    )
    emu = _with(EMULATOR, skipped_periods=120, stats__lateness_s=_ring(8e-4))
    v = judge(ctl, emu, T_S, steal_fraction=0.2)
    assert not v.valid
    assert v.reasons == [
        "controller LOOP_OVERRUN fail-safe 1× (limit 0)",
        "controller skipped 399 periods (limit 5, 0.001 of its periods)",
        "emulator skipped 120 periods (limit 4, 0.001 of its periods)",
        "controller woke up late: p99 2100 µs (limit 500 µs)",
        "emulator woke up late: p99 800 µs (limit 500 µs)",
        "host steal time 20.0 % (limit 5 %)",
    ]
    line = v.line()
    assert line.startswith("realtime: NOT VALID — controller LOOP_OVERRUN fail-safe 1×")
    assert "--lockstep" in line and "quieter host" in line


def test_each_threshold_is_read_from_the_thresholds_object() -> None:
    """Tightened thresholds turn the clean run invalid, one reason per field."""
    tight = RealtimeThresholds(
        overrun_failsafes=0,
        sensor_trips=0,
        skipped_fraction=1e-4,
        lateness_p99_periods=0.05,
        steal_fraction=0.001,
    )
    v = judge(CONTROLLER, EMULATOR, T_S, steal_fraction=0.01, thresholds=tight)
    assert len(v.reasons) == 5, v.reasons
    assert "controller skipped 2 periods (limit 0, 0.0001 of its periods)" in v.reasons
    assert "controller woke up late: p99 120 µs (limit 50 µs)" in v.reasons
    for f in fields(RealtimeThresholds):
        assert f.metadata["unit"] and f.metadata["origin"], f.name


def test_lockstep_is_valid_whatever_the_counters_say() -> None:
    ctl = _with(CONTROLLER, skipped_periods=10_000, watchdog_trips_by_reason={"LOOP_OVERRUN": 5})
    v = judge(ctl, None, T_S, lockstep=True, steal_fraction=0.9)
    assert v.valid and v.reasons == [LOCKSTEP_REASON]
    assert v.line() == f"realtime: valid ({LOCKSTEP_REASON})"


def test_a_missing_emulator_summary_and_unmeasured_steal_judge_the_controller_alone() -> None:
    assert judge(CONTROLLER, None, T_S, steal_fraction=None).valid
    nan = _with(CONTROLLER, stats__lateness_s={"n": 0, "p50": float("nan"), "p99": float("nan")})
    assert judge(nan, None, T_S).valid


def test_the_watchdog_counts_trips_by_reason_and_knows_a_silence_after_its_last_trip() -> None:
    """What ``watchdog_trips_by_reason`` and ``watchdog_trip_at_end`` in the summary come from."""
    wd = SensorWatchdog(Watchdog(timeout_cycles=3, recovery_cycles=2, auto_recover=True), max_skipped=15)
    for _ in range(3):
        wd.update(False)
    assert wd.silent_since_trip  # a sensor timeout, nothing since
    for _ in range(2):
        wd.update(True)
    assert not wd.tripped and not wd.silent_since_trip
    wd.skip(20)  # an overrun beyond what the predictors bridge
    for _ in range(3):
        wd.update(True)
    for _ in range(3):
        wd.update(False)  # the emulator ends: the last trip
    assert wd.trips_by_reason == {"SENSOR_TIMEOUT": 2, "LOOP_OVERRUN": 1} and wd.overrun_trips == 1
    assert wd.silent_since_trip
    wd.update(True)
    assert not wd.silent_since_trip  # a frame came after it: a trip of the run itself


def test_a_scenario_that_drops_frames_on_purpose_is_known_as_such() -> None:
    """Its watchdog trips are then the scenario's (as offline), not the host's."""
    sc = ROOT / "scenarios"
    assert loses_frames(load_scenario(sc / "extra" / "unseen-blackouts.yaml"))  # an event's loss
    assert loses_frames(load_scenario(sc / "extra" / "unseen-frameloss2pct.yaml"))
    assert not loses_frames(load_scenario(sc / "case2-drift.yaml"))


def test_several_runs_are_valid_only_when_each_is_and_each_reason_names_its_run() -> None:
    """The demo's verdict over its nrc and mmac runs."""
    ok = judge(CONTROLLER, EMULATOR, T_S)
    bad = judge(_with(CONTROLLER, skipped_periods=9), EMULATOR, T_S)
    assert combine({"nrc": ok, "mmac": ok}).valid
    v = combine({"nrc": ok, "mmac": bad})
    assert not v.valid and v.reasons == ["mmac: controller skipped 9 periods (limit 5, 0.001 of its periods)"]
    lock = judge({}, None, T_S, lockstep=True)
    assert combine({"nrc": lock, "mmac": lock}).reasons == [LOCKSTEP_REASON]
