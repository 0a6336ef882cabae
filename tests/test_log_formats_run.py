"""BLF and MF4 logs written by the real programs: ``ehpss-hil report`` on a lockstep run's
emulator log written as BLF, and as MF4, prints the RMS of the same run's candump
``controller.log`` (to the printed digit, over as many samples); the controller and the
emulator write the format ``--log-format`` or the suffix asks for (python-can's BLFReader
reads the BLF, asammdf opens the MF4). No timing is asserted.

The run's emulator writes the binary log because ``ehpss-hil run`` watches the controller's
candump log for its boot-up heartbeat before it starts the emulator.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import can
import pytest
from _proc import STARTUP_LIMIT_S
from _scenarios import short_scenario_yaml

from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.canlog import read_frames, read_sidecar
from ehpss_hil.cli import main
from ehpss_hil.codec import FrameCodec
from ehpss_hil.orchestrate import RunPlan, check_exit_codes, execute

ROOT = Path(__file__).resolve().parent.parent
NETNS_SKIP = netns_unavailable_reason()
_RMS = re.compile(r"RMS error (\d+\.\d+) µm")


def _lockstep_run(out: Path, emulator_log: str) -> Path:
    """A 1.5-s mmac lockstep run (LOE 50 % at 0.5 s) whose emulator logs to ``emulator_log``."""
    scenario = out.parent / "short-loe.yaml"
    scenario.write_text(short_scenario_yaml("short-loe", 1.5, "{t_s: 0.5, k_loe: 0.5}"))
    plan = RunPlan(
        scenario_path=scenario,
        mode="mmac",
        out_dir=out,
        lockstep=True,
        extra_emulator_args=("--log", str(out / emulator_log)),
        finish_timeout_s=STARTUP_LIMIT_S,  # a hang guard: a loaded VM takes its time
        startup_timeout_s=STARTUP_LIMIT_S,
    )
    check_exit_codes(execute(plan))
    return out


def _report(log: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[str, int]:
    """``ehpss-hil report``'s printed RMS (µm, as printed) and its sample count."""
    rc = main(["report", str(log), "--out", str(out), "--no-figures"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    found = [m.group(1) for ln in cap.out.splitlines() if (m := _RMS.match(ln))]
    assert len(found) == 1, cap.out
    samples = json.loads((out / "metrics.json").read_text())[0]["extra"]["samples"]
    return found[0], int(samples)


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
@pytest.mark.parametrize("fmt", ["blf", "mf4"])
def test_a_run_logged_as_blf_or_mf4_reports_the_candump_log_s_rms(
    fmt: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    if fmt == "mf4":
        pytest.importorskip("asammdf")
    run = _lockstep_run(tmp_path / "run", f"emulator.{fmt}")
    log = run / f"emulator.{fmt}"
    side = read_sidecar(log)
    assert side is not None and side["format"] == fmt.upper() and side["counts"]["dropped"] == 0
    assert side["counts"]["written"] == len(list(read_frames(log))) > 1500 * 3
    rms, samples = _report(run / "controller.log", tmp_path / "candump", capsys)
    assert 0.0 < float(rms) < 5.0 and samples == 1500  # µm: the 1 mm sine tracked
    assert _report(log, tmp_path / fmt, capsys) == (rms, samples)


def _program(argv: list[str], cwd: Path) -> None:
    """Run a program for 0.3 s on python-can's in-process virtual bus (exit 0 asserted)."""
    proc = subprocess.run(
        [sys.executable, "-m", *argv, "--interface", "virtual", "--duration", "0.3"],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=STARTUP_LIMIT_S,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_the_controller_and_the_emulator_write_the_format_asked_for(tmp_path: Path) -> None:
    """The controller's BLF holds its boot-up heartbeat (BLFReader); the emulator's MF4, asked
    for with --log-format, holds its SENSOR_POS frames (asammdf opens it)."""
    asammdf = pytest.importorskip("asammdf")
    ctrl = tmp_path / "controller.blf"
    _program(
        ["ehpss_hil.cli", "controller", "-c", str(ROOT / "configs" / "controller.yaml"), "--log", str(ctrl)],
        tmp_path,
    )
    with can.BLFReader(ctrl) as reader:
        assert 0x701 in {m.arbitration_id for m in reader}
    emu = tmp_path / "emulator.mf4"
    argv = ["firmware_sim.cli", "-c", str(ROOT / "configs" / "emulator.yaml"), "--log", str(emu)]
    _program([*argv, "--log-format", "mf4"], tmp_path)
    mdf = asammdf.MDF(emu)
    try:
        ids = {int(i) & 0x1FFFFFFF for i in mdf.get("CAN_DataFrame.ID", raw=True).samples}
    finally:
        mdf.close()
    assert FrameCodec().can_id("SENSOR_POS") in ids
    assert read_sidecar(emu)["format"] == "MF4"  # type: ignore[index]
