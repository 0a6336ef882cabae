"""``ehpss-hil report`` on a log whose wall clock stepped mid-run: the VALVE_CMD CycleCount is
the time base, the steps are undone and named in one note, the metrics are the undisturbed
log's. Logs from the lockstep sample-log writer (real frames through the DBC)."""

from __future__ import annotations

import argparse
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_report_log import short_case1

from ehpss_hil.canlog import decode_log
from ehpss_hil.canlog.reader import FRAME_INDEX
from ehpss_hil.codec import FrameCodec
from ehpss_hil.commands import report
from ehpss_hil.report.logclock import undo_clock_steps
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.report.logmetrics import log_metrics
from ehpss_hil.sim.samplelog import write_lockstep_log

_STAMP = re.compile(r"\((\d+\.\d+)\)(.*)", re.S)


@pytest.fixture(scope="module")
def clean_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_lockstep_log(short_case1(), "mmac", tmp_path_factory.mktemp("clock") / "run.log")


def _stepped(src: Path, dst: Path, steps: list[tuple[float, float]], keep: str = "") -> Path:
    """A copy of ``src`` (and its sidecar) whose timestamps jump by ``dt`` (s) from line
    ``fraction·n`` on, for each ``(fraction, dt)``; lines whose text contains ``keep``'s
    complement are dropped when ``keep`` is a frame ID to drop (``" 120#"``: VALVE_CMD)."""
    lines = [ln for ln in src.read_text().splitlines(keepends=True) if not keep or keep not in ln]
    out = []
    for i, ln in enumerate(lines):
        m = _STAMP.fullmatch(ln)
        assert m is not None
        t = float(m.group(1)) + sum(dt for frac, dt in steps if i >= frac * len(lines))
        out.append(f"({t:017.6f}){m.group(2)}")
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text("".join(out))
    shutil.copy(src.with_name(src.name + ".json"), dst.with_name(dst.name + ".json"))
    return dst


def _report(log: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[dict[str, object], list[str]]:
    p = argparse.ArgumentParser()
    report.add_arguments(p)
    assert report.run(p.parse_args([str(log), "--out", str(out), "--no-figures"])) == 0
    notes = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("note: ")]
    row: dict[str, object] = json.loads((out / "metrics.json").read_text())[0]
    return row, notes


def test_report_rms_survives_forward_and_backward_clock_steps(
    clean_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """+1 h in the middle of the file, then back by 1 h 0.5 s three quarters in: the RMS, the
    peaks and the sample count equal the undisturbed log's, and one note names both steps."""
    clean, clean_notes = _report(clean_log, tmp_path / "clean", capsys)
    assert clean_notes == [] and 0.0 < float(clean["rms_error_m"]) < 5e-6  # type: ignore[arg-type]
    log = _stepped(clean_log, tmp_path / "stepped" / "run.log", [(0.5, 3600.0), (0.75, -3600.5)])
    row, notes = _report(log, tmp_path / "rep", capsys)
    assert row["rms_error_m"] == clean["rms_error_m"]
    assert row["pre_fault_max_m"] == clean["pre_fault_max_m"]
    assert row["events"] == clean["events"] and row["extra"] == clean["extra"]
    assert len(notes) == 1, notes
    assert "clock stepped +3600.000 s" in notes[0] and "-3600.500 s" in notes[0]
    assert "CycleCount" in notes[0]


def test_the_steps_are_found_where_they_are_in_the_file(clean_log: Path, tmp_path: Path) -> None:
    n = len(clean_log.read_text().splitlines())
    log = _stepped(clean_log, tmp_path / "s" / "run.log", [(0.3, 7.25), (0.6, -20.0)])
    frames = decode_log(log, FrameCodec(), order=True)
    steps, notes = undo_clock_steps(frames, 1e-3)
    assert [(s.frame_index, s.step_s) for s in steps] == [
        (int(np.ceil(0.3 * n)), 7.25),
        (int(np.ceil(0.6 * n)), -20.0),
    ]
    clean = decode_log(clean_log, FrameCodec())
    for name, f in frames.items():  # every timestamp back where the clean log has it
        np.testing.assert_allclose(f["t_s"], clean[name]["t_s"], rtol=0, atol=2e-6)
        assert np.all(np.diff(f[FRAME_INDEX]) > 0)
    assert len(notes) == 1


def test_a_clean_log_and_a_real_pause_are_left_alone(clean_log: Path, tmp_path: Path) -> None:
    """No step in a clean log; a forward jump without VALVE_CMD (no counter spans it: it may be
    a pause of every sender) is reported and kept, a backward one is undone."""
    frames = decode_log(clean_log, FrameCodec(), order=True)
    assert undo_clock_steps(frames, None) == ([], [])
    log = _stepped(clean_log, tmp_path / "n" / "run.log", [(0.5, 30.0), (0.8, -45.0)], keep=" 120#")
    frames = decode_log(log, FrameCodec(), order=True)
    before = {k: f["t_s"].copy() for k, f in frames.items()}
    steps, notes = undo_clock_steps(frames, None)
    assert len(steps) == 1 and -45.001 < steps[0].step_s <= -45.0
    assert len(notes) == 2 and "forward by +30.00" in notes[1] and "kept as logged" in notes[1]
    t = frames["PLANT_TRUTH"]
    late = t[FRAME_INDEX] >= steps[0].frame_index
    np.testing.assert_allclose(t["t_s"][late] - before["PLANT_TRUTH"][late], 45.0, atol=1e-3)
    np.testing.assert_array_equal(t["t_s"][~late], before["PLANT_TRUTH"][~late])


def test_load_log_run_notes_the_step(clean_log: Path, tmp_path: Path) -> None:
    log = _stepped(clean_log, tmp_path / "l" / "run.log", [(0.5, 3600.0)])
    run = load_log_run(log)
    assert len(run.notes) == 1 and "+3600.000 s" in run.notes[0]
    m, ref = log_metrics(run).run, log_metrics(load_log_run(clean_log)).run
    assert m is not None and ref is not None and m.rms_error_m == ref.rms_error_m


@pytest.mark.parametrize("lockstep", [True, False])
def test_the_sidecar_decides_whether_a_gap_is_a_pause(
    clean_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], lockstep: bool
) -> None:
    """The same +2 s gap at half the file and −45 s at 0.8: with ``lockstep: true`` in the
    sidecar (as the controller daemon writes it) the gap is a pause — kept, no note — and only
    the backward jump is undone (in file order); with ``lockstep: false`` both are clock steps
    found on the CycleCount. Either way the RMS is the clean log's."""
    clean, _ = _report(clean_log, tmp_path / "clean", capsys)
    log = _stepped(clean_log, tmp_path / "g" / "run.log", [(0.5, 2.0), (0.8, -45.0)])
    side = log.with_name(log.name + ".json")
    side.write_text(json.dumps({**json.loads(side.read_text()), "lockstep": lockstep}))
    frames = decode_log(log, FrameCodec(), order=True)
    steps, notes = undo_clock_steps(frames, 1e-3, lockstep)
    sizes = [s.step_s for s in steps]
    if lockstep:
        assert len(sizes) == 1 and -45.001 < sizes[0] <= -45.0
        assert len(notes) == 1 and "file order" in notes[0] and "lockstep" in notes[0]
    else:
        assert sizes == [2.0, -45.0] and "CycleCount" in notes[0]
    row, report_notes = _report(log, tmp_path / "rep", capsys)
    assert row["rms_error_m"] == clean["rms_error_m"]
    assert len(report_notes) == 1 and ("+2.000 s" in report_notes[0]) is not lockstep
