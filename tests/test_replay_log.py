"""``ehpss-hil replay``: identical configuration → bit-identical commands; a changed mode or a
tampered frame → the first divergence, at the right cycle."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.canlog import CandumpLogger, read_log
from ehpss_hil.codec import FrameCodec
from ehpss_hil.commands import replay
from ehpss_hil.report.samplelog import write_lockstep_log
from ehpss_hil.scenario import Scenario, load_scenario


def short_case3() -> Scenario:
    """Paper case 3 (drift 0.8, then LOE 50 %) cut to 1.0 s: both channels' banks switch."""
    sc = load_scenario(PROJECT_ROOT / "scenarios" / "case3-combined.yaml")
    events = tuple(replace(ev, t_s=0.3 + 0.3 * i) for i, ev in enumerate(sc.events[:2]))
    return replace(sc, duration_s=1.0, events=events)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("replay")
    return {m: write_lockstep_log(short_case3(), m, d / m / "run.log")
            for m in ("mmac", "mmac-paper", "nrc")}


@pytest.mark.parametrize("mode", ["mmac", "mmac-paper", "nrc"])
def test_same_config_is_bit_identical(logs: dict[str, Path], mode: str) -> None:
    res = replay.replay_log(logs[mode])
    assert res.setup.mode == mode  # read from CTRL_STATUS
    assert res.cycles == 1000 and res.identical, res.first


def test_other_mode_reports_first_divergence(logs: dict[str, Path],
                                             capsys: pytest.CaptureFixture[str]) -> None:
    p = argparse.ArgumentParser()
    replay.add_arguments(p)
    assert replay.run(p.parse_args([str(logs["mmac"]), "--mode", "nrc"])) == 1
    out = capsys.readouterr().out
    assert "DIVERGED" in out and "first divergence" in out and "cycle " in out


def test_tampered_command_is_pinpointed(logs: dict[str, Path], tmp_path: Path) -> None:
    """Re-encode VALVE_CMD of cycle 400 (valid CRC, same counter) with a current 1 mA off."""
    codec = FrameCodec()
    cmd_id = codec.can_id("VALVE_CMD")
    out = tmp_path / "run.log"
    n = 0
    with CandumpLogger(out, iface="vcan0") as lg:
        for msg in read_log(logs["nrc"]):
            if msg.arbitration_id == cmd_id:
                if n == 400:
                    v = codec.message("VALVE_CMD").decode(bytes(msg.data))
                    v["CurrentSetpoint"] += 1e-3
                    msg = codec.encode("VALVE_CMD", {k: v[k] for k in (
                        "CurrentSetpoint", "Enable", "SensorCounterEcho", "CycleCount")},
                        timestamp_s=msg.timestamp, counter=msg.data[1] & 0xF)
                n += 1
            lg.log(msg)
    res = replay.replay_log(out, mode="nrc", scenario=None)
    assert res.divergent == 1 and res.first[0].cycle == 400
    assert res.first[0].logged_a - res.first[0].replayed_a == pytest.approx(1e-3, abs=1e-6)


def test_controller_library_missing_is_a_clear_error(logs: dict[str, Path],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    import sys
    monkeypatch.setitem(sys.modules, "ehpss_hil.control.controllers", None)
    with pytest.raises(replay.ReplayError, match="controller library not available"):
        replay.replay_log(logs["nrc"])
