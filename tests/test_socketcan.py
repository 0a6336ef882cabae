"""SocketCAN path (docs/design.md §11): real ``socketcan`` buses on vcan0, real processes, our log.

Runs natively where ``socket(AF_CAN)`` works and vcan0 is up; on kernels without SocketCAN
``.ci/run`` runs this module inside ``../shared/tools/vcan-vm/run`` (a QEMU VM with vcan0/vcan1).
Python is ~10–25× slower inside that VM: nothing here is timed, bounds are loose.
"""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest
from _proc import STARTUP_LIMIT_S, lockstep_plan
from _scenarios import short_scenario_yaml
from _vcan import vcan_reason

from ehpss_hil.bus import open_bus
from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.config import BusConfig
from ehpss_hil.orchestrate import check_exit_codes, execute
from ehpss_hil.run_metrics import metrics_from_run

pytestmark = pytest.mark.socketcan


@pytest.fixture
def vcan0() -> str:
    reason = vcan_reason()
    if reason is not None:
        pytest.skip(reason)
    return "vcan0"


def test_socketcan_bus_applies_the_projects_filters(vcan0: str) -> None:
    codec = FrameCodec()
    wanted = [codec.can_id("SENSOR_POS"), codec.can_id("SENSOR_AUX")]
    filters = [{"can_id": i, "can_mask": 0x7FF, "extended": False} for i in wanted]
    cfg = BusConfig(interface="socketcan", channel=vcan0)
    rx = open_bus(cfg, can_filters=filters)
    tx = open_bus(cfg)
    try:
        sent = [
            codec.encode("SENSOR_POS", {"Position": 1e-3, "Spool": 2e-4}),
            codec.encode("VALVE_CMD", {"CurrentSetpoint": 1e-4, "Enable": 1}),
            codec.encode("SENSOR_AUX", {"CoilCurrent": 1e-4}),
            codec.encode("HEARTBEAT_EMU", {"NmtState": 5}),
        ]
        for m in sent:
            tx.send(m)
        got: list[can.Message] = []
        while (r := rx.recv(timeout=2.0)) is not None:
            got.append(r)
            if len(got) == 2:
                break
        assert rx.recv(timeout=0.3) is None  # VALVE_CMD and the heartbeat were filtered out
        assert [m.arbitration_id for m in got] == wanted
        check = FrameCodec()
        assert [check.classify(m).verdict for m in got] == [Verdict.OK, Verdict.OK]
    finally:
        rx.shutdown()
        tx.shutdown()


SHORT = short_scenario_yaml("vcan-short", 0.6, "{t_s: 0.3, k_loe: 0.5}")


def test_controller_and_emulator_processes_on_vcan0(vcan0: str, tmp_path: Path) -> None:
    sc = tmp_path / "short.yaml"
    sc.write_text(SHORT)
    out = tmp_path / "run"
    res = execute(lockstep_plan(sc, out, "mmac", interface="socketcan", channel=vcan0))
    check_exit_codes(res)
    row = metrics_from_run(out)
    assert row["unavailable"] == []
    assert row["rms_error_m"] < 50e-6  # loose: lockstep, 1 mm sine, LOE 50 % at 0.3 s
    assert len(row["events"]) == 1
    # our candump log of the run reads back with python-can's reader and our codec
    frames = list(can.CanutilsLogReader(out / "bus.log"))
    codec = FrameCodec()
    names = [codec.name_of(m.arbitration_id) for m in frames]
    n_cmd, n_pos = names.count("VALVE_CMD"), names.count("SENSOR_POS")
    assert n_pos >= 600 and n_cmd >= 600
    verdicts = [codec.classify(m).verdict for m in frames]
    assert all(v.usable for v in verdicts)
    summary = json.loads((out / "emulator-summary.json").read_text())
    assert summary["periods"] >= 600


#: the down-and-up test's loop rate (Hz): the VM's Python is ~10x slower than the host's, and at
#: 100 Hz a controller there overran often enough to stay starved in its fail-safe
VCAN_RATE_HZ = 50
VCAN_CTRL_YAML = """\
bus: {{interface: socketcan, channel: {channel}}}
mode: nrc
rate_hz: {rate}
reference: {{kind: sine, amplitude_m: 0.0002, omega_rad_s: 5.0}}
watchdog: {{timeout_cycles: 5, recovery_cycles: 20, auto_recover: true, failsafe: zero}}
params: {root}/configs/params.yaml
dbc: {root}/dbc/ehpss.dbc
"""
VCAN_SLOW_SCENARIO = """\
name: vcan-slow
duration_s: 600
sample_time_s: {ts}
seed: 1
reference: {{kind: sine, amplitude_m: 0.0002, omega_rad_s: 5.0}}
"""


def test_vcan0_down_for_a_second_is_a_bus_error_and_recovers(vcan0: str, tmp_path: Path) -> None:
    """vcan0 taken down for 1 s under a running controller (50 Hz: the VM's Python is slow):
    fail-safe BUS_ERROR (its sends fail with ENETDOWN), ACTIVE again once vcan0 is up
    (auto_recover), SIGTERM → exit 0 with the counts in its summary."""
    import subprocess
    import time

    from _proc import EHPSS_HIL, FIRMWARE_SIM, ROOT, Proc

    ctl_cfg = tmp_path / "controller.yaml"
    ctl_cfg.write_text(VCAN_CTRL_YAML.format(channel=vcan0, root=ROOT, rate=VCAN_RATE_HZ))
    sc = tmp_path / "slow.yaml"
    sc.write_text(VCAN_SLOW_SCENARIO.format(ts=1.0 / VCAN_RATE_HZ))
    bus = ["--interface", "socketcan", "--channel", vcan0]
    emu_cfg = str(ROOT / "configs" / "emulator.yaml")
    emu = Proc([*FIRMWARE_SIM, "-c", emu_cfg, *bus, "--rate", str(VCAN_RATE_HZ), "--scenario", str(sc)])
    ctl: Proc | None = None
    try:
        assert emu.wait_for("realtime on", STARTUP_LIMIT_S), emu.text
        summary = tmp_path / "ctl.json"
        ctl = Proc([*EHPSS_HIL, "controller", "-c", str(ctl_cfg), "--summary-json", str(summary)])
        assert ctl.wait_for("first sensor data: ACTIVE", STARTUP_LIMIT_S), ctl.text + emu.text
        subprocess.run(["ip", "link", "set", vcan0, "down"], check=True)
        time.sleep(1.0)
        subprocess.run(["ip", "link", "set", vcan0, "up"], check=True)
        assert ctl.wait_for("bus healthy for", STARTUP_LIMIT_S), ctl.text
        assert ctl.wait_for("ACTIVE again", STARTUP_LIMIT_S), ctl.text
        ctl.terminate()
        assert ctl.wait() == 0, ctl.text
        emu.terminate()
        emu.wait()
    finally:
        subprocess.run(["ip", "link", "set", vcan0, "up"], check=False)
        for p in (ctl, emu):
            if p is not None and p.p.poll() is None:
                p.p.kill()
                p.p.wait()
    assert "bus error" in ctl.text and "BUS_ERROR" in ctl.text, ctl.text
    health = json.loads(summary.read_text())["bus_health"]
    assert health["episodes"] >= 1 and health["tx_errors"] > 0, health
