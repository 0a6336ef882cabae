"""``ehpss-hil replay``: identical configuration → bit-identical commands; a changed mode or a
tampered frame → the first divergence, at the right cycle."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import pytest
from _dbc import signal_values

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.canlog import CandumpLogger, read_log
from ehpss_hil.codec import FrameCodec
from ehpss_hil.commands import replay
from ehpss_hil.replay.engine import ReplayError, replay_log
from ehpss_hil.scenario import Scenario, load_scenario
from ehpss_hil.sim.samplelog import write_lockstep_log


def short_case3() -> Scenario:
    """Paper case 3 (drift 0.8, then LOE 50 %) cut to 1.0 s: both channels' banks switch."""
    sc = load_scenario(PROJECT_ROOT / "scenarios" / "case3-combined.yaml")
    events = tuple(replace(ev, t_s=0.3 + 0.3 * i) for i, ev in enumerate(sc.events[:2]))
    return replace(sc, duration_s=1.0, events=events)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("replay")
    return {m: write_lockstep_log(short_case3(), m, d / m / "run.log") for m in ("mmac", "mmac-paper", "nrc")}


@pytest.mark.parametrize("mode", ["mmac", "mmac-paper", "nrc"])
def test_same_config_is_bit_identical(logs: dict[str, Path], mode: str) -> None:
    res = replay_log(logs[mode])
    assert res.setup.mode == mode  # read from CTRL_STATUS
    assert res.cycles == 1000 and res.identical, res.first


def test_other_mode_reports_first_divergence(
    logs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
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
                    v = signal_values(codec.message("VALVE_CMD"), msg.data)
                    v["CurrentSetpoint"] += 1e-3
                    msg = codec.encode(
                        "VALVE_CMD",
                        {k: v[k] for k in ("CurrentSetpoint", "Enable", "SensorCounterEcho", "CycleCount")},
                        timestamp_s=msg.timestamp,
                        counter=msg.data[1] & 0xF,
                    )
                n += 1
            lg.log(msg)
    res = replay_log(out, mode="nrc", scenario=None)
    assert res.divergent == 1 and res.first[0].cycle == 400
    assert res.first[0].logged_a - res.first[0].replayed_a == pytest.approx(1e-3, abs=1e-6)


def test_skipped_periods_replay_bit_identical(tmp_path: Path) -> None:
    """A realtime-style log with controller overruns (CycleCount gaps): the daemon stepped the
    skipped periods without data; the replay does the same and matches bit for bit."""
    import can

    from ehpss_hil.control.registry import make_controller
    from ehpss_hil.emulation import PlantEmulation
    from ehpss_hil.physics.load import load_params
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
        emu = EmulatorProcess(
            PlantEmulation(params, sc), FrameIO(eb, FrameCodec(), EMU_FRAMES), EmulatorOptions()
        )
        logger = CandumpLogger(
            out,
            iface="vcan0",
            sidecar={"scenario": str(PROJECT_ROOT / "scenarios" / "case3-combined.yaml"), "rate_hz": 1000.0},
        )
        loop = ControllerLoop(
            make_controller("mmac", params, 1e-3, None, sc.reference),
            FrameIO(cb, FrameCodec(), OWN_FRAMES, logger),
            sc.reference,
            LoopOptions(),
        )
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
    res = replay_log(out)
    assert res.skipped_periods == loop.skipped_periods
    assert res.cycles > 900 and res.identical, res.first


LOSSY = PROJECT_ROOT / "scenarios" / "extra" / "unseen-frameloss2pct.yaml"


def _lossy(sensor: float, command: float) -> Scenario:
    """2 % loss scenario cut to 1.2 s, with the given loss per direction."""
    sc = load_scenario(LOSSY)
    return replace(
        sc,
        duration_s=1.2,
        frame_loss=0.0,
        sensor_frame_loss=sensor,
        command_frame_loss=command,
        events=tuple(e for e in sc.events if e.t_s <= 1.2),
    )


@pytest.mark.parametrize("mode", ["nrc", "smac", "mmac-paper", "mmac"])
@pytest.mark.parametrize(("sensor", "command"), [(0.05, 0.0), (0.0, 0.05), (0.03, 0.03)])
def test_lossy_lockstep_logs_replay_exactly(tmp_path: Path, mode: str, sensor: float, command: float) -> None:
    """Lost sensor frames (a cycle without data, then a sample count of 2 from the E2E counter)
    and lost VALVE_CMDs (a CycleCount gap: cycles that ran, commands that never arrived) replay
    bit for bit; before the one driver 3025 / 1037 of 3500 cycles diverged."""
    log = write_lockstep_log(_lossy(sensor, command), mode, tmp_path / "run.log")
    res = replay_log(log)
    assert res.identical, (res.divergent, res.first)
    assert (res.skipped_periods > 0) == (command > 0)
    assert res.cycles + res.skipped_periods == 1200


def _reordered_like_candump(src: Path, dst: Path) -> int:
    """candump -L writes the vcan echo of a VALVE_CMD after the next sensor pair: move each
    VALVE_CMD line below the two sensor lines that follow it (timestamps untouched)."""
    codec = FrameCodec()
    cmd, aux = codec.can_id("VALVE_CMD"), codec.can_id("SENSOR_AUX")
    lines = src.read_text().splitlines(keepends=True)
    out: list[str] = []
    pending: list[str] = []
    moved = 0
    for line in lines:
        fid = int(line.split()[2].split("#")[0], 16)
        if fid == cmd:
            pending.append(line)
            continue
        out.append(line)
        if fid == aux and pending:  # the next sensor pair has been written: now the command
            out.extend(pending)
            moved += len(pending)
            pending = []
    out.extend(pending)
    dst.write_text("".join(out))
    return moved


def test_replay_pairs_commands_by_content_not_file_order(tmp_path: Path) -> None:
    log = write_lockstep_log(_lossy(0.03, 0.0), "mmac", tmp_path / "run.log")
    shuffled = tmp_path / "candump-order.log"
    assert _reordered_like_candump(log, shuffled) > 1000
    (tmp_path / "candump-order.log.json").write_text((tmp_path / "run.log.json").read_text())
    res = replay_log(shuffled)
    assert res.identical, (res.divergent, res.first)


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_python_can_formats_replay_exactly(tmp_path: Path, suffix: str) -> None:
    """The same run written by python-can's own writers (no sidecar: the scenario and mode are
    given) replays bit for bit."""
    import can

    log = write_lockstep_log(_lossy(0.03, 0.0), "mmac", tmp_path / "run.log")
    other = tmp_path / f"run{suffix}"
    with can.Logger(str(other)) as writer:
        for msg in read_log(log):
            writer.on_message_received(msg)
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(LOSSY.read_text().replace("duration_s: 4.0", "duration_s: 1.2"))
    sc = load_scenario(scenario)
    assert sc.reference == _lossy(0.03, 0.0).reference
    res = replay_log(other, mode="mmac", scenario=scenario)
    assert res.identical, (res.divergent, res.first)


@pytest.mark.parametrize(("name", "data"), [("broken.blf", b"LOGG" + b"\x00" * 60), ("frames.xyz", b"hello")])
def test_unreadable_log_is_one_line_exit_2(
    tmp_path: Path, name: str, data: bytes, capsys: pytest.CaptureFixture[str]
) -> None:
    from ehpss_hil.cli import main

    (tmp_path / name).write_bytes(data)
    assert main(["replay", str(tmp_path / name), "--mode", "nrc"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0], err


def test_oracle_is_not_replayable(logs: dict[str, Path]) -> None:
    with pytest.raises(ReplayError, match="not replayable"):
        replay_log(logs["nrc"], mode="oracle")
