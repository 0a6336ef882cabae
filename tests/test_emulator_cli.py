"""``firmware-sim`` as a real OS process: exit codes, SIGTERM, and cross-process runs against a
small test client on ``udp_multicast`` inside a private network namespace (``unshare --net``)."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest
from _proc import CLIENT, FIRMWARE_SIM, ROOT, Proc
from _scenarios import short_scenario_yaml

from ehpss_hil.bus import af_can_available
from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason

EMU_CFG = str(ROOT / "configs" / "emulator.yaml")
NETNS_SKIP = netns_unavailable_reason()
netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")


def test_bad_config_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "emulator.yaml"
    bad.write_text("rate_hz: 1000\ncommand_timeout_s: -1\n")
    p = Proc([*FIRMWARE_SIM, "-c", str(bad)])
    assert p.wait() == 2
    assert "command_timeout_s" in p.text
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("bus: {interface: udp_multicast, channel: 224.1.1.1}\n")
    p = Proc([*FIRMWARE_SIM, "-c", str(unknown)])
    assert p.wait() == 2 and "bus.channel" in p.text


@pytest.mark.skipif(af_can_available(), reason="this kernel has SocketCAN: vcan99 might exist")
def test_missing_interface_exits_3() -> None:
    p = Proc([*FIRMWARE_SIM, "-c", EMU_CFG, "--interface", "socketcan", "--channel", "vcan99"])
    assert p.wait() == 3
    assert "SocketCAN" in p.text


def test_sigterm_exits_0_with_counters() -> None:
    p = Proc([*FIRMWARE_SIM, "-c", EMU_CFG, "--interface", "virtual", "--channel", "sigterm"])
    try:
        assert p.wait_for("realtime on virtual"), p.text
        p.p.send_signal(signal.SIGTERM)
        assert p.wait() == 0, p.text
    finally:
        p.kill()
    assert "frames sent" in p.text and "lateness p50" in p.text


def test_realtime_with_a_scenario_ends_at_its_duration(tmp_path: Path) -> None:
    """``firmware-sim --scenario S`` in realtime (no peer, no ``--duration``) ends by itself after
    S's 0.3 s of plant time, exit 0, all 300 periods accounted (executed or skipped)."""
    sc = tmp_path / "short.yaml"
    sc.write_text(short_scenario_yaml("short", 0.3, "{t_s: 0.1, k_loe: 0.5}"))
    summary = tmp_path / "emu.json"
    args = [
        "--interface",
        "virtual",
        "--channel",
        "ends",
        "--scenario",
        str(sc),
        "--summary-json",
        str(summary),
    ]
    p = Proc([*FIRMWARE_SIM, "-c", EMU_CFG, *args])
    try:
        assert p.wait(limit_s=120.0) == 0, p.text
    finally:
        p.kill()
    assert json.loads(summary.read_text())["periods"] == 300


@netns
def test_realtime_emulator_and_client_processes(tmp_path: Path) -> None:
    log = tmp_path / "emu.log"
    summary = tmp_path / "emu.json"
    with PrivateNetns() as ns:
        client = Proc(ns.prefix() + CLIENT + ["--pairs", "1500"])
        emu = None
        try:
            assert client.wait_for("ready"), client.text
            emu = Proc(
                ns.prefix()
                + FIRMWARE_SIM
                + ["-c", EMU_CFG, "--log", str(log), "--summary-json", str(summary)]
            )
            assert client.wait() == 0, client.text
            emu.p.send_signal(signal.SIGTERM)
            assert emu.wait() == 0, emu.text
        finally:
            client.kill()
            if emu is not None:
                emu.kill()
    c = json.loads(client.out[-1])
    s = json.loads(summary.read_text())
    assert c["answered"] == 1500
    assert c["received"]["OK"] + c["received"]["OK_SOME_LOST"] >= 3000
    assert s["frames_sent"]["SENSOR_POS"] >= 1500
    assert s["commands_accepted"] >= 1  # (how many arrive in time is not asserted: no timing)
    assert s["received_by_verdict"]["CRC_ERROR"] == 1  # the client's one corrupted command
    from ehpss_hil.canlog import read_log

    ids = {m.arbitration_id for m in read_log(log)}
    assert {0x110, 0x111, 0x120} <= ids  # sensor frames sent and commands received, logged


@netns
def test_lockstep_emulator_and_client_processes(tmp_path: Path) -> None:
    summary = tmp_path / "emu.json"
    with PrivateNetns() as ns:
        client = Proc(ns.prefix() + CLIENT + ["--idle", "1", "--no-bad"])
        emu = None
        try:
            assert client.wait_for("ready"), client.text
            emu = Proc(
                ns.prefix()
                + FIRMWARE_SIM
                + ["-c", EMU_CFG, "--mode", "lockstep", "--duration", "0.5", "--summary-json", str(summary)]
            )
            assert emu.wait() == 0, emu.text
            assert client.wait() == 0, client.text
        finally:
            client.kill()
            if emu is not None:
                emu.kill()
    s = json.loads(summary.read_text())
    assert s["periods"] == 500 and s["commands_accepted"] == 500
    assert s["command_timeouts"] == 0 and s["frames_sent"]["SENSOR_POS"] == 500
    assert json.loads(client.out[-1])["answered"] == 500
