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


def test_skipped_periods_replay_bit_identical(tmp_path: Path) -> None:
    """A realtime-style log with controller overruns (CycleCount gaps): the daemon stepped the
    skipped periods without data; the replay does the same and matches bit for bit."""
    import can

    from ehpss_hil.control.registry import make_controller
    from ehpss_hil.emulation import PlantEmulation
    from ehpss_hil.physics.params import load_params
    from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
    from ehpss_hil.runtime.frameio import FrameIO
    from firmware_sim.process import OWN_FRAMES as EMU_FRAMES
    from firmware_sim.process import EmulatorOptions, EmulatorProcess

    sc = short_case3()
    params = load_params()
    out = tmp_path / "controller.log"
    eb = can.Bus(interface="virtual", channel="replay-skips")
    cb = can.Bus(interface="virtual", channel="replay-skips")
    try:
        emu = EmulatorProcess(PlantEmulation(params, sc), FrameIO(eb, FrameCodec(), EMU_FRAMES),
                              EmulatorOptions())
        logger = CandumpLogger(out, iface="vcan0", sidecar={"scenario": str(
            PROJECT_ROOT / "scenarios" / "case3-combined.yaml"), "rate_hz": 1000.0})
        loop = ControllerLoop(make_controller("mmac", params, 1e-3, None, sc.reference),
                              FrameIO(cb, FrameCodec(), OWN_FRAMES, logger), sc.reference,
                              LoopOptions())
        k = 0
        while emu.periods < sc.n_samples - 3:
            skipped = 2 if k % 97 == 50 else 0  # an overrun now and then: 2 periods slept through
            for _ in range(skipped + 1):
                emu.step_period()
            loop.poll_cycle(skipped)
            k += 1
        loop.io.close()
    finally:
        eb.shutdown()
        cb.shutdown()
    assert loop.skipped_periods >= 18
    res = replay.replay_log(out)
    assert res.skipped_periods == loop.skipped_periods
    assert res.cycles > 900 and res.identical, res.first
