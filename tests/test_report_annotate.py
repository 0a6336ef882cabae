"""Reports an engineer reads at a glance (issue #20 item 4): fault events in words, FAULT and
fallback intervals with their reasons, NRC vs MMAC overlaid, numbers to their resolution, a
self-contained HTML report, and ``sim --plot`` writing exactly the files it names."""

from __future__ import annotations

import argparse
import base64
import re
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.canlog.reader import parse_line
from ehpss_hil.codec import FrameCodec
from ehpss_hil.commands import report, sim
from ehpss_hil.report.annotate import Interval, describe_changes, event_labels, intervals
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.report.logviews import log_view
from ehpss_hil.scenario import Scenario, load_scenario
from ehpss_hil.sim.lockstep import run_scenario
from ehpss_hil.sim.samplelog import write_lockstep_log

pytest.importorskip("matplotlib")

#: the wall-clock window (s after the log's first frame) rewritten to FAULT / SENSOR_TIMEOUT
FAULT_FROM_S, FAULT_TO_S = 0.3, 0.5


def case3_short() -> Scenario:
    """Paper case 3 (drift 0.8 at 1 s, LOE 50 % at 2 s) compressed to 1.2 s: events at 0.4, 0.8."""
    sc = load_scenario(PROJECT_ROOT / "scenarios" / "case3-combined.yaml")
    return replace(
        sc, duration_s=1.2, events=(replace(sc.events[0], t_s=0.4), replace(sc.events[1], t_s=0.8))
    )


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"k_loe": 0.5}, "LOE 50 %"),
        ({"k_loe": 0.3}, "LOE 70 %"),
        ({"k_dft": 0.8}, "drift 0.8"),
        ({"k_dft": 0.0}, "sensor failed"),
        ({"k_q": 0.7}, "k_Q 0.7"),
        ({"stuck": True}, "sensor stuck"),
        ({"k_loe": 1.0}, "LOE cleared"),
        ({"k_dft": 0.8, "k_loe": 0.5}, "drift 0.8 + LOE 50 %"),
        ({"position_bias_m": 0.0005}, "sensor bias 0.5 mm"),
        ({"sensor_frame_loss": 0.2}, "sensor loss 20 %"),
    ],
)
def test_fault_changes_in_words(changes: dict[str, float], words: str) -> None:
    assert describe_changes(changes) == words


def test_intervals_by_code() -> None:
    t = np.arange(10, dtype=float)  # s
    codes = np.array([0, 2, 2, 0, 0, 3, 3, 3, 2, 2], float)
    got = intervals(t, codes, "FAULT", {2: "A", 3: "B"})
    assert got == [
        Interval(1.0, 3.0, "FAULT", "A"),
        Interval(5.0, 8.0, "FAULT", "B"),
        Interval(8.0, 10.0, "FAULT", "A"),  # the last ends one sample after its last sample
    ]


def test_event_labels_from_the_scenario_or_from_the_true_gains() -> None:
    sc = case3_short()
    r = run_scenario(sc, "mmac")
    assert event_labels(r, sc.events) == [(0.4, "drift 0.8"), (0.8, "LOE 50 %")]
    # without the scenario: what PLANT_FAULTS-style true gains say changed at each event
    assert event_labels(r) == [(0.4, "drift 0.8"), (0.8, "LOE 50 %")]


def _with_fault(log: Path, out: Path) -> Path:
    """``log`` with its CTRL_STATUS frames in the FAULT window re-encoded as State FAULT,
    FailsafeReason SENSOR_TIMEOUT (same counters: the log stays E2E-valid)."""
    rx, tx = FrameCodec(), FrameCodec()
    status_id = tx.can_id("CTRL_STATUS")
    lines = log.read_text().splitlines()
    t0 = float(lines[0].split(")")[0][1:])
    new = []
    for line in lines:
        msg = parse_line(line + "\n")
        if msg is not None and msg.arbitration_id == status_id:
            d = rx.classify(msg)
            if d.values is not None and FAULT_FROM_S <= msg.timestamp - t0 < FAULT_TO_S:
                v = {**d.values, "State": 3, "FailsafeReason": 1}
                enc = tx.encode("CTRL_STATUS", v, counter=msg.data[1] & 0x0F)
                line = f"{line.split('#')[0]}#{enc.data.hex().upper()}"
        new.append(line)
    out.write_text("\n".join(new) + "\n")
    shutil.copy(str(log) + ".json", str(out) + ".json")
    return out


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("case3")
    sc = case3_short()
    (d / "mmac").mkdir()
    (d / "nrc").mkdir()
    mmac = write_lockstep_log(sc, "mmac", d / "mmac" / "raw.log")
    return {
        "mmac": _with_fault(mmac, d / "mmac" / "bus.log"),
        "nrc": write_lockstep_log(sc, "nrc", d / "nrc" / "bus.log"),
    }


def test_a_logged_fault_interval_with_its_reason(logs: dict[str, Path]) -> None:
    run = load_log_run(logs["mmac"])
    view = log_view(run)
    assert view.events == [(pytest.approx(0.4), "drift 0.8"), (pytest.approx(0.8), "LOE 50 %")]
    faults = [iv for iv in view.intervals if iv.kind == "FAULT"]
    assert len(faults) == 1 and faults[0].reason == "SENSOR_TIMEOUT"
    # on the controller's time axis, within one CTRL_STATUS period (20 ms) of the rewritten window
    ts = run.result.ts_s
    assert faults[0].t0_s == pytest.approx(FAULT_FROM_S, abs=0.02 + 2 * ts)
    assert faults[0].t1_s == pytest.approx(FAULT_TO_S, abs=0.02 + 2 * ts)


def test_report_overlays_modes_and_writes_a_self_contained_html(
    logs: dict[str, Path], tmp_path: Path
) -> None:
    p = argparse.ArgumentParser()
    report.add_arguments(p)
    out = tmp_path / "rep"
    args = [str(logs["mmac"]), "--compare", str(logs["nrc"]), "--out", str(out)]
    assert report.run(p.parse_args(args)) == 0
    md = (out / "report.md").read_text()
    assert "![compare](figures/compare.png)" in md
    assert "- events: drift 0.8 at 0.400 s; LOE 50 % at 0.800 s" in md
    rows = [ln for ln in md.splitlines() if ln.startswith("| mmac |") or ln.startswith("| nrc |")]
    assert len(rows) == 2
    assert re.search(r"\| 0\.3\d\d s \| 0\.5\d\d s \| FAULT \| SENSOR_TIMEOUT \|", md), md
    assert not re.search(r"\d\.\d{7,}", md), "a number printed to more digits than it carries"
    html = (out / "report.html").read_text()
    figures = re.findall(r"!\[[^]]*\]\(([^)]+)\)", md)
    embedded = re.findall(r'src="data:image/png;base64,([^"]+)"', html)
    assert len(embedded) == len(figures) >= 7 and "figures/" not in html
    assert base64.b64decode(embedded[0]) == (out / figures[0]).read_bytes()


def test_sim_plot_writes_the_files_it_names(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = argparse.ArgumentParser()
    sim.add_arguments(p)
    case1 = str(PROJECT_ROOT / "scenarios" / "case1-loe.yaml")
    case2 = str(PROJECT_ROOT / "scenarios" / "case2-drift.yaml")
    one = tmp_path / "one.png"
    assert sim.run(p.parse_args([case1, "-C", "nrc", "-C", "mmac", "--plot", str(one), "-j", "1"])) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["one.png"]
    assert f"wrote {one}" in capsys.readouterr().out
    two = tmp_path / "two" / "fig.png"
    two.parent.mkdir()
    assert sim.run(p.parse_args([case1, case2, "-C", "mmac", "--plot", str(two), "-j", "1"])) == 0
    names = sorted(p.name for p in two.parent.iterdir())
    assert names == ["fig-case1-loe.png", "fig-case2-drift.png"]
    printed = capsys.readouterr().out
    assert all(f"wrote {two.parent / n}" in printed for n in names)
