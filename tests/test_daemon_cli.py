"""``ehpss-hil controller`` as a real OS process: exit codes, SIGTERM → zero current and exit 0,
and cross-process runs with the emulator on ``udp_multicast`` inside ``unshare --net``."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import pytest
from _proc import EHPSS_HIL, FIRMWARE_SIM, ROOT, Proc

from ehpss_hil.bus import af_can_available
from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason

CTRL_CFG = str(ROOT / "configs" / "controller.yaml")
EMU_CFG = str(ROOT / "configs" / "emulator.yaml")
CONTROLLER = [*EHPSS_HIL, "controller", "-c", CTRL_CFG]
NETNS_SKIP = netns_unavailable_reason()
netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")


def test_bad_config_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "controller.yaml"
    bad.write_text("mode: oracle\n")
    p = Proc([*EHPSS_HIL, "controller", "-c", str(bad)])
    assert p.wait() == 2 and "mode" in p.text
    p = Proc([*CONTROLLER, "--rate", "5"])
    assert p.wait() == 2 and "rate_hz" in p.text


@pytest.mark.skipif(af_can_available(), reason="this kernel has SocketCAN: vcan99 might exist")
def test_missing_interface_exits_3() -> None:
    p = Proc([*CONTROLLER, "--interface", "socketcan", "--channel", "vcan99"])
    assert p.wait() == 3 and "SocketCAN" in p.text


def test_sigterm_exits_0() -> None:
    p = Proc([*CONTROLLER, "--interface", "virtual", "--channel", "daemon-sigterm"])
    try:
        assert p.wait_for("on virtual:daemon-sigterm"), p.text
        p.p.send_signal(signal.SIGTERM)
        assert p.wait() == 0, p.text
    finally:
        p.kill()
    assert "final state STOPPED" in p.text


@netns
def test_lockstep_controller_and_emulator_processes(tmp_path: Path) -> None:
    emu_json, ctl_json = tmp_path / "emu.json", tmp_path / "ctl.json"
    with PrivateNetns() as ns:
        ctl = Proc(ns.prefix() + CONTROLLER + ["--lockstep", "--summary-json", str(ctl_json)])
        emu = None
        try:
            assert ctl.wait_for("(lockstep)"), ctl.text
            emu = Proc(
                ns.prefix()
                + FIRMWARE_SIM
                + [
                    "-c",
                    EMU_CFG,
                    "--mode",
                    "lockstep",
                    "--duration",
                    "0.5",
                    "--scenario",
                    str(ROOT / "scenarios" / "case1-loe.yaml"),
                    "--summary-json",
                    str(emu_json),
                ]
            )
            assert emu.wait() == 0, emu.text
            ctl.p.send_signal(signal.SIGTERM)
            assert ctl.wait() == 0, ctl.text
        finally:
            ctl.kill()
            if emu is not None:
                emu.kill()
    e, c = json.loads(emu_json.read_text()), json.loads(ctl_json.read_text())
    assert e["periods"] == 500 and e["commands_accepted"] == 500 and e["command_timeouts"] == 0
    assert c["cycles"] == 500 and c["state"] == "STOPPED" and c["watchdog_trips"] == 0


def _start_pair(ns: PrivateNetns, tmp: Path) -> tuple[Proc, Proc]:
    emu = Proc(
        ns.prefix()
        + FIRMWARE_SIM
        + ["-c", EMU_CFG, "--log", str(tmp / "emu.log"), "--summary-json", str(tmp / "emu.json")]
    )
    assert emu.wait_for("realtime on"), emu.text
    ctl = Proc(
        ns.prefix() + CONTROLLER + ["--log", str(tmp / "ctl.log"), "--summary-json", str(tmp / "ctl.json")]
    )
    assert ctl.wait_for("first sensor data: ACTIVE"), ctl.text + emu.text
    time.sleep(1.0)  # let them run (nothing below depends on how long)
    return emu, ctl


@netns
def test_realtime_sigterm_leaves_valve_at_zero(tmp_path: Path) -> None:
    from ehpss_hil.canlog import read_log
    from ehpss_hil.codec import FrameCodec

    with PrivateNetns() as ns:
        emu, ctl = _start_pair(ns, tmp_path)
        try:
            ctl.p.send_signal(signal.SIGTERM)
            assert ctl.wait() == 0, ctl.text  # its last VALVE_CMD is in the emulator's socket
            emu.p.send_signal(signal.SIGTERM)  # the emulator drains + logs it before exiting
            assert emu.wait() == 0, emu.text
        finally:
            ctl.kill()
            emu.kill()
    codec = FrameCodec()
    cmds = [
        codec.classify(m)
        for m in read_log(tmp_path / "emu.log")
        if m.arbitration_id == codec.can_id("VALVE_CMD")
    ]
    assert len(cmds) > 10
    last = cmds[-1].values
    assert last is not None and last["Enable"] == 0 and last["CurrentSetpoint"] == 0.0
    c = json.loads((tmp_path / "ctl.json").read_text())
    assert c["state"] == "STOPPED"  # one VALVE_CMD per executed cycle, + the final one
    assert c["frames_sent"]["VALVE_CMD"] == c["cycles"] - c["skipped_periods"] + 1
    ctl_ids = {m.arbitration_id for m in read_log(tmp_path / "ctl.log")}
    assert {0x110, 0x111, 0x120, 0x140} <= ctl_ids


@netns
def test_emulator_killed_controller_fails_safe(tmp_path: Path) -> None:
    with PrivateNetns() as ns:
        emu, ctl = _start_pair(ns, tmp_path)
        try:
            emu.kill()  # SIGKILL: no goodbye frames
            # the shipped 3-cycle watchdog: on a loaded host the controller's own overrun may
            # have tripped it (LOOP_OVERRUN) before the kill; it stays in fail-safe then
            assert ctl.wait_for(" -> FAULT"), ctl.text
            ctl.p.send_signal(signal.SIGTERM)
            assert ctl.wait() == 0, ctl.text
        finally:
            ctl.kill()
            emu.kill()
    c = json.loads((tmp_path / "ctl.json").read_text())
    assert c["watchdog_trips"] == 1 and c["failsafe_reason"] in ("SENSOR_TIMEOUT", "LOOP_OVERRUN")
    assert c["failsafe_cycles"] >= 1


@pytest.mark.socketcan
@pytest.mark.skipif(not af_can_available(), reason="no SocketCAN (socket(AF_CAN) failed)")
def test_lockstep_processes_on_vcan0(tmp_path: Path) -> None:
    """The production interface: emulator and controller processes in lockstep on vcan0."""
    emu_json, ctl_json = tmp_path / "emu.json", tmp_path / "ctl.json"
    vcan = ["--interface", "socketcan", "--channel", "vcan0"]
    ctl = Proc([*CONTROLLER, *vcan, "--lockstep", "--summary-json", str(ctl_json)])
    emu = None
    try:
        assert ctl.wait_for("(lockstep)", limit_s=300), ctl.text
        emu = Proc(
            [
                *FIRMWARE_SIM,
                "-c",
                EMU_CFG,
                *vcan,
                "--mode",
                "lockstep",
                "--duration",
                "0.05",
                "--lockstep-timeout",
                "120",
                "--summary-json",
                str(emu_json),
            ]
        )
        assert emu.wait(limit_s=300) == 0, emu.text
        ctl.p.send_signal(signal.SIGTERM)
        assert ctl.wait(limit_s=300) == 0, ctl.text
    finally:
        ctl.kill()
        if emu is not None:
            emu.kill()
    e, c = json.loads(emu_json.read_text()), json.loads(ctl_json.read_text())
    assert e["periods"] == 50 and e["commands_accepted"] == 50
    assert c["cycles"] == 50 and c["state"] == "STOPPED"
