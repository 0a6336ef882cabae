"""``ehpss-hil report`` on generated bench logs: metrics agree with the lockstep simulation,
figures are real PNGs, a log without ground truth says what it cannot give."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.canlog import CandumpLogger, read_log
from ehpss_hil.canlog.sidecar import sidecar_path
from ehpss_hil.commands import report
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.report.logmeta import reference_of
from ehpss_hil.report.logmetrics import log_metrics
from ehpss_hil.report.metrics import compute_metrics
from ehpss_hil.scenario import Scenario, load_scenario
from ehpss_hil.sim.lockstep import run_scenario
from ehpss_hil.sim.samplelog import write_lockstep_log

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def short_case1() -> Scenario:
    """Paper case 1 cut to 1.2 s with its first two LOE events (0.5 s, 1.0 s)."""
    sc = load_scenario(PROJECT_ROOT / "scenarios" / "case1-loe.yaml")
    events = (sc.events[0], replace(sc.events[1], t_s=1.0))
    return replace(sc, duration_s=1.2, events=events)


@pytest.fixture(scope="module")
def bench_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_lockstep_log(short_case1(), "mmac", tmp_path_factory.mktemp("bench") / "run.log")


def _run_report(log: Path, out: Path, *extra: str) -> int:
    p = argparse.ArgumentParser()
    report.add_arguments(p)
    return report.run(p.parse_args([str(log), "--out", str(out), *extra]))


def test_log_metrics_match_the_lockstep_simulation(bench_log: Path) -> None:
    sc = short_case1()
    run = load_log_run(bench_log)
    assert run.has_truth and run.has_reference and not run.notes
    sim = run_scenario(sc, "mmac", transport="frames")
    r = run.result
    assert r.event_times_s == pytest.approx([0.5, 1.0])
    np.testing.assert_array_equal(r.y_m_m, sim.y_m_m)  # same reference model, same samples
    np.testing.assert_allclose(r.x_true_m, sim.x_true_m, atol=0.5e-7)  # PLANT_TRUTH LSB 0.1 µm
    np.testing.assert_array_equal(run.commanded_current_a[:-1], sim.current_a[1:])  # delay 1
    m = log_metrics(run).run
    ref = compute_metrics(sim)
    assert m is not None
    assert m.rms_error_m == pytest.approx(ref.rms_error_m, abs=1e-7)
    assert m.pre_fault_max_m == pytest.approx(ref.pre_fault_max_m, abs=1e-7)
    for a, b in zip(m.events, ref.events, strict=True):
        assert a.peak_error_m == pytest.approx(b.peak_error_m, abs=1e-7)


def test_report_writes_metrics_markdown_and_pngs(bench_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "rep"
    assert _run_report(bench_log, out, "--json", str(tmp_path / "m.json")) == 0
    rows = json.loads((tmp_path / "m.json").read_text())
    assert rows[0]["scenario"] == "case1-loe" and rows[0]["controller"] == "mmac"
    assert rows[0]["rms_error_m"] > 0 and len(rows[0]["events"]) == 2
    md = (out / "report.md").read_text()
    assert "RMS error" in md and "![error](figures/error.png)" in md
    pngs = sorted((out / "figures").glob("*.png"))
    assert {p.stem for p in pngs} == {
        "overview",
        "position",
        "error",
        "current",
        "models",
        "estimates",
        "index",
    }
    for p in pngs:
        data = p.read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000


def test_report_without_ground_truth(tmp_path: Path) -> None:
    log = write_lockstep_log(short_case1(), "mmac", tmp_path / "run.log", truth=False)
    run = load_log_run(tmp_path)  # a directory works too
    m = log_metrics(run)
    assert not run.has_truth and m.run is None
    assert any("PLANT_TRUTH" in u for u in m.unavailable)
    assert m.extra["sensor_rms_error_m"] > 0 and "switches_counter" in m.extra
    assert _run_report(log, tmp_path / "rep") == 0
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "ground truth (PLANT_TRUTH): NO" in md and "not available" in md
    assert (tmp_path / "rep" / "figures" / "error.png").stat().st_size > 10_000


def test_missing_commands_and_no_reference(bench_log: Path, tmp_path: Path) -> None:
    """Drop 5 VALVE_CMD frames and the sidecar: the grid stays uniform and the notes say why
    no tracking metric can be given."""
    log = tmp_path / "cut.log"
    cmd_id = 0x120
    with CandumpLogger(log, iface="vcan0") as lg:
        n_cmd = 0
        for msg in read_log(bench_log):
            if msg.arbitration_id == cmd_id:
                n_cmd += 1
                if 300 <= n_cmd < 305:
                    continue
            lg.log(msg)
    sidecar_path(log).unlink()
    run = load_log_run(log)
    assert len(run.result.t_s) == 1200
    assert np.isnan(run.commanded_current_a[299:304]).all()
    assert any("5 VALVE_CMD frames missing" in n for n in run.notes)
    assert any("no reference" in n for n in run.notes)
    assert log_metrics(run).run is None
    again = load_log_run(log, scenario=short_case1())  # --scenario supplies it
    assert log_metrics(again).run is not None


def test_reference_from_a_scenario_name(tmp_path: Path) -> None:
    """firmware-sim writes only the scenario's name: it is looked up in scenarios/."""
    sc, ref, ts = reference_of({"scenario": "case2-drift"}, tmp_path)
    assert sc is not None and sc.name == "case2-drift" and ts == sc.sample_time_s
    sc, ref, ts = reference_of(
        {"config": {"reference": {"kind": "sine", "amplitude_m": 0.002}, "rate_hz": 2000}}, tmp_path
    )
    assert sc is None and ref is not None and ref.amplitude_m == 0.002 and ts == 0.0005


def test_reference_from_a_run_directory(bench_log: Path, tmp_path: Path) -> None:
    """A bus log without scenario in its sidecar, inside an ``ehpss-hil run`` directory: the
    reference comes from ``run.json``; outside such a directory nothing is borrowed."""
    log = tmp_path / "bus.log"
    with CandumpLogger(log, iface="vcan0", sidecar={"tool": "ehpss-hil log"}) as lg:
        for msg in read_log(bench_log):
            lg.log(msg)
    assert not load_log_run(log).has_reference
    (tmp_path / "run.json").write_text(
        json.dumps({"scenario_path": str(PROJECT_ROOT / "scenarios" / "case1-loe.yaml")})
    )
    run = load_log_run(log)
    assert run.has_reference and run.scenario is not None and run.scenario.name == "case1-loe"
    assert any("run.json" in n for n in run.notes)
    _, ref, ts = reference_of({"config": str(PROJECT_ROOT / "configs" / "controller.yaml")}, tmp_path)
    assert ref is not None and ts == pytest.approx(1e-3)


def test_the_answer_to_the_last_sample_with_truth_counts_however_late() -> None:
    """The rows scored against the ground truth end 1.5 periods after the emulator's last
    PLANT_TRUTH frame — and, on a loaded host, the answer to the last sample sent with it may
    come later (a lockstep run's last command logged 5 ms after its truth frame: 1499 of 1500
    samples under stress-ng). That row is kept; the fail-safe cycles after the emulator stopped
    (no sensor frame since the row before them) are not, in one chunk or across chunks."""
    from ehpss_hil.report.logdata import rows_with_truth

    ts = 1e-3
    truth_last, sensors = 1.0, np.array([0.998, 0.999, 1.0])
    late = np.array([0.9982, 0.9991, 1.0052, 1.0063, 1.0074])  # the answer to 1.0 came 5.2 ms late
    assert rows_with_truth(late, truth_last, sensors, ts).tolist() == [True, True, True, False, False]
    timely = np.array([0.9995, 1.0004, 1.0014, 1.0024, 1.0034])  # realtime: fail-safe cycles after
    assert rows_with_truth(timely, truth_last, sensors, ts).tolist() == [True, True, True, False, False]
    # a streamed chunk that starts at the late row: the row before it is the last chunk's
    assert rows_with_truth(late[2:], truth_last, sensors, ts, t_before=0.9991).tolist() == [
        True,
        False,
        False,
    ]
    assert rows_with_truth(late[3:], truth_last, sensors, ts, t_before=1.0052).tolist() == [False, False]
