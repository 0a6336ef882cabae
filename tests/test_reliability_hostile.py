"""Hostile surroundings (issue #16): stray datagrams on the embedded bus, foreign files in a run
directory, a full disk under the logs. Real processes in a private network namespace; nothing
here is timed (waits have generous limits only so that a broken run fails)."""

from __future__ import annotations

from pathlib import Path

import pytest
from _scenarios import short_scenario_yaml

from ehpss_hil.reliability.hostile import (
    FOREIGN,
    disk_full_trial,
    foreign_files_trial,
    tmpfs_unavailable_reason,
)
from ehpss_hil.reliability.procs import skip_reason
from ehpss_hil.reliability.stray import KINDS, stray_trial
from ehpss_hil.runtime.rtverdict import REALTIME_INVALID_EXIT

SKIP = skip_reason()
FS_SKIP = tmpfs_unavailable_reason()
needs_netns = pytest.mark.skipif(SKIP is not None, reason=str(SKIP))


@needs_netns
def test_stray_datagrams_are_counted_and_no_process_ends(tmp_path: Path) -> None:
    r = stray_trial(tmp_path, rounds=2)
    assert not r.error, r.error
    assert r.sent == 2 * len(KINDS)
    assert r.alive == {"logger": True, "controller": True, "emulator": True}
    assert r.exits == {"emulator": 0, "controller": 0, "logger": 0}
    assert r.counted == dict.fromkeys(("controller", "emulator", "logger", "controller log"), r.sent)
    assert r.ok


@pytest.fixture(scope="module")
def short_scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("hostile") / "short.yaml"
    p.write_text(short_scenario_yaml("short", 0.5, "{t_s: 0.3, k_loe: 0.5}"))
    return p


@needs_netns
def test_run_never_removes_foreign_files(tmp_path: Path, short_scenario: Path) -> None:
    r = foreign_files_trial(tmp_path, short_scenario)
    assert r.refused_exit == 2 and len(r.refused_lines) == 1, r.refused_lines
    assert "--overwrite" in r.refused_lines[0]
    assert r.kept_after_refusal == r.kept_after_run == len(FOREIGN)
    # 4: the run completed but this (loaded) host did not hold the rate; its files are written
    assert r.overwrite_exit in (0, REALTIME_INVALID_EXIT) and r.run_files == 3
    assert r.ok


@pytest.mark.skipif(SKIP is not None or FS_SKIP is not None, reason=str(SKIP or FS_SKIP))
def test_full_disk_under_the_logs_exit_0_exact_sidecars_whole_lines(tmp_path: Path) -> None:
    r = disk_full_trial(tmp_path, seconds=3.0)
    assert not r.error, r.error
    assert r.exits == {"emulator": 0, "controller": 0}
    assert r.summaries == {"controller": True, "emulator": True}
    for name, st in r.logs.items():
        assert st.whole_lines and st.status == "closed", (name, st)
        assert st.written == st.lines, (name, st)
    assert r.dropped > 0 and r.warned and not r.tmp_left
    assert r.ok
