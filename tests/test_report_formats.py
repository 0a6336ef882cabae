"""``ehpss-hil report`` on real runs' logs in every format python-can reads, and its clock rule.

The logs come from ``ehpss-hil run`` (real processes on the embedded bus, private network
namespace): the candump ``-L`` log, the same frames written by python-can's ``.asc`` and ``.blf``
writers give the same printed RMS; a 2-s pause put into a lockstep log is a pause (same RMS,
no clock-step note), with its sidecar or, as a candump of a lockstep run without one, judged
from the timing; a +1 h wall-clock step in a realtime log (CycleCount running on) is still
found and undone. A log that yields no sample is one line and exit 2. No timing is asserted.
"""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import can
import numpy as np
import pytest
from _proc import STARTUP_LIMIT_S
from _scenarios import short_scenario_yaml

from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.canlog import lockstep_of, read_frames, read_sidecar
from ehpss_hil.cli import main
from ehpss_hil.codec import FrameCodec
from ehpss_hil.orchestrate import RunPlan, check_exit_codes, execute
from ehpss_hil.report.logclock import REALTIME_RATE_TOLERANCE, unwrap_counter

NETNS_SKIP = netns_unavailable_reason()
needs_netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")

SHORT = short_scenario_yaml("short-loe", 1.5, "{t_s: 0.5, k_loe: 0.5}")
_STAMP = re.compile(r"\((\d+\.\d+)\)(.*)", re.S)
_RMS = re.compile(r"RMS error (\d+\.\d+) µm")


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("formats") / "short-loe.yaml"
    p.write_text(SHORT)
    return p


def _run(scenario: Path, out: Path, lockstep: bool) -> Path:
    plan = RunPlan(
        scenario_path=scenario,
        mode="mmac",
        out_dir=out,
        lockstep=lockstep,
        finish_timeout_s=STARTUP_LIMIT_S,  # a hang guard: a loaded VM takes its time
        startup_timeout_s=STARTUP_LIMIT_S,
    )
    check_exit_codes(execute(plan))
    return out


@pytest.fixture(scope="module")
def lockstep_run(scenario: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    if NETNS_SKIP is not None:
        pytest.skip(NETNS_SKIP)
    return _run(scenario, tmp_path_factory.mktemp("lockstep") / "run", lockstep=True)


@pytest.fixture(scope="module")
def realtime_run(scenario: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    if NETNS_SKIP is not None:
        pytest.skip(NETNS_SKIP)
    return _run(scenario, tmp_path_factory.mktemp("realtime") / "run", lockstep=False)


def _report(
    log: Path, out: Path, capsys: pytest.CaptureFixture[str], *extra: str
) -> tuple[int, list[str], str]:
    """``ehpss-hil report`` through the CLI: (exit code, stdout lines, stderr)."""
    rc = main(["report", str(log), "--out", str(out), "--no-figures", *extra])
    cap = capsys.readouterr()
    return rc, cap.out.splitlines(), cap.err


def _rms(lines: list[str]) -> str:
    """The printed RMS (µm, as printed)."""
    found = [m.group(1) for ln in lines if (m := _RMS.match(ln))]
    assert len(found) == 1, lines
    return found[0]


def _notes(lines: list[str]) -> list[str]:
    return [ln for ln in lines if ln.startswith("note: ")]


def _shifted(src: Path, dst: Path, fraction: float, dt_s: float, sidecar: bool = True) -> Path:
    """A copy of the candump log ``src`` whose timestamps from line ``fraction``·n on are
    ``dt_s`` later (the frames, their CycleCount included, unchanged); with its sidecar."""
    lines = src.read_text().splitlines(keepends=True)
    out = []
    for i, ln in enumerate(lines):
        m = _STAMP.fullmatch(ln)
        assert m is not None, ln
        t = float(m.group(1)) + (dt_s if i >= fraction * len(lines) else 0.0)
        out.append(f"({t:017.6f}){m.group(2)}")
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text("".join(out))
    if sidecar:
        shutil.copy(src.with_name(src.name + ".json"), dst.with_name(dst.name + ".json"))
    return dst


def _wall_per_cycle(log: Path) -> float:
    """Median wall time (s) per counted VALVE_CMD cycle of a log."""
    codec = FrameCodec()
    cmd_id = codec.can_id("VALVE_CMD")
    t, cc = [], []
    for msg in read_frames(log):
        if msg.arbitration_id == cmd_id:
            d = codec.classify(msg)
            if d.values is not None:
                t.append(msg.timestamp)
                cc.append(int(d.values["CycleCount"]))
    k = unwrap_counter(np.array(cc))
    ok = np.diff(k) > 0
    return float(np.median(np.diff(t)[ok] / np.diff(k)[ok]))


@needs_netns
def test_the_run_metadata_says_lockstep_or_realtime(lockstep_run: Path, realtime_run: Path) -> None:
    """The controller's and the emulator's sidecars and run.json say how the run's clock ran;
    the bus logger's sidecar does not (report takes it from run.json beside it)."""
    for run, lockstep in ((lockstep_run, True), (realtime_run, False)):
        for name in ("controller.log", "emulator.log"):
            assert lockstep_of(read_sidecar(run / name)) is lockstep
        assert lockstep_of(json.loads((run / "run.json").read_text())) is lockstep
        assert lockstep_of(read_sidecar(run / "bus.log")) is None


@needs_netns
def test_candump_asc_and_blf_give_the_same_report(
    lockstep_run: Path, scenario: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The run's candump log and the same frames written by python-can as .asc and .blf (no
    sidecar: --scenario gives the reference) print the same RMS over the same samples; no line
    is skipped, report.md holds text only and no "pass --scenario" hint."""
    log = lockstep_run / "controller.log"
    rc, out, _ = _report(log, tmp_path / "log", capsys)
    assert rc == 0
    rms = _rms(out)
    assert 0.0 < float(rms) < 5.0  # µm: the 1 mm sine tracked (metrics: RMS a few 0.1 µm)
    samples = json.loads((tmp_path / "log" / "metrics.json").read_text())[0]["extra"]["samples"]
    assert samples == 1500
    msgs = list(read_frames(log))
    for suffix in (".asc", ".blf"):
        other = tmp_path / f"controller{suffix}"
        with can.Logger(str(other)) as writer:
            for msg in msgs:
                writer.on_message_received(msg)
        rc, lines, err = _report(other, tmp_path / suffix, capsys, "--scenario", str(scenario))
        assert rc == 0, err
        assert _rms(lines) == rms, (suffix, lines)
        row = json.loads((tmp_path / suffix / "metrics.json").read_text())[0]
        assert row["extra"]["samples"] == samples
        assert not any("bad line" in n or "pass --scenario" in n for n in lines), lines
        md = (tmp_path / suffix / "report.md").read_text()
        assert all(c.isprintable() or c == "\n" for c in md)
        assert f"controller{suffix}" in md and "pass --scenario" not in md


@needs_netns
@pytest.mark.parametrize("sidecar", [True, False], ids=["sidecar", "candump-without-sidecar"])
def test_a_pause_in_a_lockstep_log_is_no_clock_step(
    lockstep_run: Path,
    scenario: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    sidecar: bool,
) -> None:
    """Every timestamp from half the file on 2 s later: the same RMS and no clock-step note —
    the sidecar says lockstep, or (no sidecar) the wall clock does not keep the cycle clock."""
    log = lockstep_run / "controller.log"
    if not sidecar and abs(_wall_per_cycle(log) / 1e-3 - 1.0) <= REALTIME_RATE_TOLERANCE:
        pytest.skip("this lockstep run happened to go at real time: only its metadata tells")
    _, clean, _ = _report(log, tmp_path / "clean", capsys)
    paused = _shifted(log, tmp_path / "paused" / "controller.log", 0.5, 2.0, sidecar)
    extra = () if sidecar else ("--scenario", str(scenario))
    rc, lines, err = _report(paused, tmp_path / "rep", capsys, *extra)
    assert rc == 0, err
    assert _rms(lines) == _rms(clean)
    notes = _notes(lines)
    assert not any("clock stepped" in n or "jump" in n for n in notes), notes
    assert any("taken as a lockstep run" in n for n in notes) is not sidecar


@needs_netns
def test_a_wall_clock_step_in_a_realtime_log_is_still_undone(
    realtime_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """+1 h from half of a realtime log on while CycleCount runs on: one note names the step
    (sized on the CycleCount), the RMS is the unstepped log's to the printed digit."""
    log = realtime_run / "controller.log"
    _, clean, _ = _report(log, tmp_path / "clean", capsys)
    assert not any("clock stepped" in n for n in _notes(clean)), clean
    stepped = _shifted(log, tmp_path / "stepped" / "controller.log", 0.5, 3600.0)
    rc, lines, err = _report(stepped, tmp_path / "rep", capsys)
    assert rc == 0, err
    steps = [n for n in _notes(lines) if "clock stepped" in n]
    assert len(steps) == 1 and "CycleCount" in steps[0], lines
    m = re.search(r"stepped ([+-]\d+\.\d+) s", steps[0])
    assert m is not None and float(m.group(1)) == pytest.approx(3600.0, abs=0.01)
    assert float(_rms(lines)) == pytest.approx(float(_rms(clean)), abs=0.011)


def _empty_blf(p: Path) -> None:
    with can.Logger(str(p)):
        pass


_HEARTBEATS = "(1767225600.000000) can0 701#05\n(1767225600.100000) can0 702#05\n"


@pytest.mark.parametrize(
    ("name", "make", "why"),
    [
        ("empty.log", lambda p: p.write_bytes(b""), "no frame of the DBC could be read"),
        ("garbage.log", lambda p: p.write_bytes(b"hello\n\x00\xff\xfe\x01junk\n"), "2 bad line(s)"),
        ("empty.blf", _empty_blf, "no frame of the DBC could be read"),
        ("heartbeats.log", lambda p: p.write_text(_HEARTBEATS), "no usable VALVE_CMD or PLANT_TRUTH"),
    ],
)
def test_a_log_without_samples_is_one_line_exit_2(
    tmp_path: Path,
    scenario: Path,
    capsys: pytest.CaptureFixture[str],
    name: str,
    make: Callable[[Path], object],
    why: str,
) -> None:
    log = tmp_path / name
    make(log)
    rc, out, err = _report(log, tmp_path / "rep", capsys, "--scenario", str(scenario))
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and name in lines[0] and "no samples" in lines[0] and why in lines[0], err
    assert lines[0].isprintable() and "pass --scenario" not in err + "".join(out)
    assert not (tmp_path / "rep" / "report.md").exists()
