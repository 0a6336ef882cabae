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
from typing import Any

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.canlog.reader import parse_line
from ehpss_hil.codec import FrameCodec
from ehpss_hil.commands import report, sim
from ehpss_hil.reasons import FAILSAFE_COLORS, FALLBACK_COLORS
from ehpss_hil.report.annotate import Interval, describe_changes, event_labels, intervals
from ehpss_hil.report.figures import draw_runs
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.report.logviews import log_view
from ehpss_hil.scenario import Event, Scenario, load_scenario
from ehpss_hil.sim.lockstep import run_scenario
from ehpss_hil.sim.samplelog import write_lockstep_log

pytest.importorskip("matplotlib")
from matplotlib.colors import to_rgb

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


def test_scenario_events_paired_by_what_changed_not_by_time() -> None:
    """A real-time emulator's scenario clock runs ahead of the controller's: its events are
    paired with the changes the run saw by their new values, and an event the bus cannot show
    (a bias) is placed with the same offset; labelling the labelled times again changes nothing."""
    sc = case3_short()
    r = run_scenario(sc, "mmac")  # changes at 0.4 (drift 0.8) and 0.8 (LOE 50 %)
    ahead = (replace(sc.events[0], t_s=0.1), replace(sc.events[1], t_s=0.5))
    claimed = (*ahead, Event(t_s=0.6, position_bias_m=0.0005))
    got = event_labels(r, claimed)
    assert got == [
        (pytest.approx(0.4), "drift 0.8"),
        (pytest.approx(0.8), "LOE 50 %"),
        (pytest.approx(0.9), "sensor bias 0.5 mm"),
    ]
    again = replace(r, event_times_s=tuple(t for t, _ in got))
    assert event_labels(again, claimed) == got


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


def case3_stuck() -> Scenario:
    """:func:`case3_short` with the position sensor stuck at 1.0 s (no gain changes then)."""
    sc = case3_short()
    return replace(sc, events=(*sc.events, Event(t_s=1.0, stuck=True)))


def test_a_stuck_sensor_event_is_in_the_table_and_on_the_figure(tmp_path: Path) -> None:
    sc = case3_stuck()
    log = write_lockstep_log(sc, "mmac", tmp_path / "run" / "bus.log")
    run = load_log_run(log)
    # the bus shows it (PLANT_TRUTH Stuck): in the event times the metrics use, in words
    # even without the scenario (an injection from the monitor)
    assert run.result.event_times_s == pytest.approx((0.4, 0.8, 1.0), abs=2 * run.result.ts_s)
    assert event_labels(run.result)[2][1] == "sensor stuck"
    view = log_view(run)
    assert [w for _, w in view.events] == ["drift 0.8", "LOE 50 %", "sensor stuck"]
    # the figure's annotations: the event's name above the top axis at its time, a dashed line
    fig = draw_runs([view])
    names = {t.get_text(): t.xy[0] for t in fig.axes[0].texts}
    assert names["sensor stuck"] == pytest.approx(1.0, abs=2 * run.result.ts_s)
    dashed = [ln.get_xdata()[0] for ln in fig.axes[1].lines if ln.get_linestyle() == "--"]
    assert any(abs(x - 1.0) <= 2 * run.result.ts_s for x in dashed)
    import matplotlib.pyplot as plt

    plt.close(fig)
    # report.md's event table: a row at the event's time naming it
    p = argparse.ArgumentParser()
    report.add_arguments(p)
    out = tmp_path / "rep"
    assert report.run(p.parse_args([str(log), "--out", str(out)])) == 0
    md = (out / "report.md").read_text()
    assert re.search(r"^\| 1\.0\d\d \| sensor stuck \| \d+\.\d\d µm \|", md, re.M), md
    assert "sensor stuck at 1.0" in md
    html = (out / "report.html").read_text()
    assert html.count("<figcaption>") == md.count("](figures/") >= 7
    assert "<strong>FRA</strong>" in html and "<strong>RIA</strong>" in html


def test_no_estimator_traces_for_nrc_and_a_colour_per_reason(logs: dict[str, Path]) -> None:
    nrc = log_view(load_log_run(logs["nrc"]))
    mmac = log_view(load_log_run(logs["mmac"]))
    fig = draw_runs([mmac, nrc])
    labels = [ln.get_label() for a in fig.axes[3:] for ln in a.lines]
    assert any(lab.endswith(" mmac") for lab in labels)
    assert not any(lab.endswith(" nrc") for lab in labels), labels
    # k̂ of mmac is a gap inside its FAULT interval (the controller resets its estimators there)
    fault = next(iv for iv in mmac.intervals if iv.kind == "FAULT")
    k_loe = next(ln for ln in fig.axes[4].lines if ln.get_label() == "k̂_LOE mmac")
    t, y = (np.asarray(a, float) for a in k_loe.get_data())
    inside = (t >= fault.t0_s) & (t < fault.t1_s)
    assert inside.any() and np.isnan(y[inside]).all() and np.isfinite(y[~inside]).any()
    handles, names = fig.axes[-1].get_legend_handles_labels()
    span = handles[names.index("mmac FAULT: SENSOR_TIMEOUT")]
    assert to_rgb(span.get_facecolor()) == to_rgb(FAILSAFE_COLORS["SENSOR_TIMEOUT"])
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_every_dbc_reason_has_its_colour() -> None:
    codec = FrameCodec()
    for frame, signal, table in (
        ("CTRL_STATUS", "FailsafeReason", FAILSAFE_COLORS),
        ("CTRL_STATS", "FallbackReason", FALLBACK_COLORS),
    ):
        choices: Any = codec.message(frame).get_signal_by_name(signal).choices or {}
        names = {str(v) for v in choices.values()}
        assert names <= set(table), names - set(table)
    assert len(set(FAILSAFE_COLORS.values())) == len(FAILSAFE_COLORS)


def _with_acks(log: Path, out: Path, acks: list[tuple[float, dict[str, float]]]) -> Path:
    """``log`` with FAULT_INJECT_ACK frames (``(s after the first frame, values)``) inserted in
    time order, as an emulator answering the monitor's injections logs them."""
    tx = FrameCodec()
    lines = log.read_text().splitlines()
    t0 = float(lines[0].split(")")[0][1:])
    chan = lines[0].split()[1]
    for dt, values in acks:
        msg = tx.encode("FAULT_INJECT_ACK", values)
        t = t0 + dt
        i = next(i for i, ln in enumerate(lines) if float(ln.split(")")[0][1:]) > t)
        lines.insert(i, f"({t:.6f}) {chan} {msg.arbitration_id:03X}#{msg.data.hex().upper()}")
    out.write_text("\n".join(lines) + "\n")
    shutil.copy(str(log) + ".json", str(out) + ".json")
    return out


def test_an_injection_only_its_answer_shows_is_an_event(logs: dict[str, Path], tmp_path: Path) -> None:
    """A frame loss injected from the monitor changes no gain: the emulator's FAULT_INJECT_ACK
    (APPLIED) makes it an event in words, on the figures and in the table; a refused
    injection is none."""
    log = _with_acks(
        logs["nrc"],
        tmp_path / "bus.log",
        [
            (0.6, {"FaultKind": 5, "Status": 0, "Value": 0.2}),  # frame_loss 20 %, applied
            (0.7, {"FaultKind": 0, "Status": 1, "Value": 7.0}),  # k_loe 7, OUT_OF_RANGE
        ],
    )
    run = load_log_run(log)
    view = log_view(run)
    words = [w for _, w in view.events]
    assert words == ["drift 0.8", "frame loss 20 %", "LOE 50 %"], view.events
    t_loss = next(t for t, w in view.events if w == "frame loss 20 %")
    assert t_loss == pytest.approx(0.6, abs=0.005)
    assert t_loss in run.result.event_times_s  # in the metrics' event table too
    again = log_view(run)
    assert again.events == view.events
