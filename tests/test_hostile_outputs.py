"""Outputs in hostile folders (issue #16): the run directory manifest, unwritable and full
folders, logs cut short, and the console of ``ehpss-hil run`` without root / interface."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import can
import pytest
from _proc import EHPSS_HIL, ROOT

from ehpss_hil import orchestrate
from ehpss_hil.canlog import BadLines, CandumpLogger, read_log, read_sidecar
from ehpss_hil.errors import BusUnavailableError, OutputError
from ehpss_hil.reliability.hostile import SmallTmpfs, tmpfs_unavailable_reason
from ehpss_hil.rundir import MANIFEST, prepare_run_dir, record_outputs

FOREIGN = ("app.log.1", "syslog.log", "catalog.logbook", "notes.out")


def _folder(d: Path, names: tuple[str, ...]) -> Path:
    d.mkdir()
    for n in names:
        (d / n).write_text(n)
    return d


def test_foreign_folder_is_refused_and_left_alone(tmp_path: Path) -> None:
    d = _folder(tmp_path / "f", FOREIGN)
    with pytest.raises(OutputError, match="--overwrite") as e:
        prepare_run_dir(d)
    assert "\n" not in str(e.value) and e.value.exit_code == 2
    assert sorted(p.name for p in d.iterdir()) == sorted(FOREIGN)


def test_overwrite_removes_only_the_names_a_run_writes(tmp_path: Path) -> None:
    d = _folder(tmp_path / "f", (*FOREIGN, "bus.log", "bus.log.3", "run.json", "controller.out"))
    prepare_run_dir(d, overwrite=True)
    assert sorted(p.name for p in d.iterdir()) == sorted((*FOREIGN, MANIFEST))


def test_a_run_directory_is_reused_and_only_its_files_go(tmp_path: Path) -> None:
    d = tmp_path / "run"
    prepare_run_dir(d)  # made: empty but for the manifest
    (d / "bus.log").write_text("x")
    (d / "report" / "figures").mkdir(parents=True)
    (d / "report" / "figures" / "a.png").write_text("png")
    record_outputs(d, [d / "report" / "figures" / "a.png"])
    (d / "notes.out").write_text("mine")  # the user's, added later
    prepare_run_dir(d)
    assert sorted(p.name for p in d.iterdir()) == [MANIFEST, "notes.out"]


def test_unwritable_folder_is_one_line_exit_2_and_nothing_left(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(OutputError) as e:
        prepare_run_dir(blocker / "run")
    assert e.value.exit_code == 2 and "\n" not in str(e.value)
    r = subprocess.run(
        [*EHPSS_HIL, "log", "-i", "virtual", "-c", "x", "-o", str(blocker / "bus.log"), "--duration", "0.1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().count("\n") == 0 and "cannot write the log" in r.stderr
    assert r.stdout == ""


def test_bad_lines_are_skipped_and_counted(tmp_path: Path) -> None:
    log = tmp_path / "x.log"
    with CandumpLogger(log) as lg:
        for i in range(5):
            lg.log(
                can.Message(
                    arbitration_id=0x110, data=bytes([i] * 8), is_extended_id=False, timestamp=100.0 + i
                )
            )
    with open(log, "ab") as fh:  # garbage, then a last line cut in its data
        fh.write(b"garbage\n(0000000105.000000) can0 110#0102")
    bad = BadLines()
    msgs = list(read_log(log, bad=bad))
    assert [m.data[0] for m in msgs] == [0, 1, 2, 3, 4]
    assert bad.count == 2 and "x.log:6" in bad.text()


@pytest.mark.skipif(tmpfs_unavailable_reason() is not None, reason=str(tmpfs_unavailable_reason()))
@pytest.mark.parametrize("reserve", [0, 64 * 1024])
def test_full_disk_whole_lines_exact_counts_no_tmp(tmp_path: Path, reserve: int) -> None:
    """reserve 0: the writes fail with ENOSPC (cut back to the last newline); 64 KiB: the
    writer stops before the disk is full."""
    with SmallTmpfs(tmp_path / "fs") as fs:
        log = fs / "bus.log"
        lg = CandumpLogger(log, disk_reserve_bytes=reserve)
        for i in range(20_000):
            lg.log(
                can.Message(
                    arbitration_id=0x110, data=bytes(8), is_extended_id=False, timestamp=100.0 + i * 1e-3
                )
            )
        s = lg.close()
        raw = log.read_bytes()
        side = read_sidecar(log)
        assert side is not None
        assert not [p.name for p in fs.iterdir() if p.name.endswith(".tmp")]
        assert raw.endswith(b"\n") and raw.count(b"\n") == s.written > 0
        assert side["status"] == "closed" and side["counts"]["written"] == s.written
        assert s.written + s.dropped == 20_000
        assert side["counts"]["dropped_by_reason"] == {"disk full": s.dropped}
        with can.CanutilsLogReader(log) as reader:
            assert len(list(reader)) == s.written


def test_run_without_a_namespace_says_so(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(orchestrate, "netns_unavailable_reason", lambda: "not root")
    monkeypatch.setattr(orchestrate, "multicast_route_reason", lambda group="": "no route")
    with pytest.raises(BusUnavailableError):
        orchestrate._namespace("udp_multicast", quiet=False)
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no private network namespace (not root)" in err


def test_run_on_a_missing_interface_exits_3(tmp_path: Path) -> None:
    sc = ROOT / "scenarios" / "case1-loe.yaml"
    r = subprocess.run(
        [
            *EHPSS_HIL,
            "run",
            str(sc),
            "--interface",
            "socketcan",
            "--channel",
            "vcan97",
            "--out",
            str(tmp_path / "run"),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert r.returncode == 3, r.stderr
    assert r.stderr.strip().count("\n") == 0 and "vcan97" in r.stderr
    assert json.loads((tmp_path / "run" / MANIFEST).read_text())["tool"] == "ehpss-hil run"
