"""``ehpss-hil monitor`` decodes every protocol profile listen-only: a vendor valve's frames
(``dbc-map``, the emulator process impersonating the vendor electronics, udp_multicast in a
private namespace) and a CiA 408 valve's PDOs (the emulated nodes driven by ``canopen``'s own
master, heard by the monitor's codec on the same bus) show as the logical signals."""

from __future__ import annotations

import re
import time

import can
import pytest
from _cia408 import Cia408Rig, heartbeat_state, wait_until
from _proc import EHPSS_HIL, FIRMWARE_SIM, ROOT, Proc

from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason
from ehpss_hil.codec import Verdict
from ehpss_hil.config import load_controller_config
from ehpss_hil.monitor.profiles import ListenCia408Codec, monitor_codec
from ehpss_hil.monitor.state import MonitorState, choice_names
from ehpss_hil.protocol.cia408.objects import SCALE_100_PERCENT

NETNS_SKIP = netns_unavailable_reason()


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_the_monitor_decodes_a_vendor_valve_listen_only() -> None:
    with PrivateNetns() as ns:
        emu = Proc(
            ns.prefix()
            + FIRMWARE_SIM
            + ["-c", str(ROOT / "configs" / "emulator-vendor.yaml"), "--duration", "300"]
        )
        mon = None
        try:
            assert emu.wait_for("realtime on", 120.0), emu.text
            cfg = str(ROOT / "configs" / "controller-vendor.yaml")
            mon = Proc(ns.prefix() + EHPSS_HIL + ["monitor", "--tui", "--duration", "3", "--config", cfg])
            assert mon.wait(120.0) == 0, mon.text
        finally:
            if mon is not None:
                mon.kill()
            emu.kill()
    last = "".join(mon.out).rsplit("\x1b[H\x1b[2J", 1)[-1]
    y_s = re.search(r"y_s (\S+) mm", last)
    assert y_s is not None and y_s.group(1) != "–", last  # AMP_FEEDBACK.PistonPos, decoded
    verdicts = re.search(r"verdicts  (.*)", last)
    assert verdicts is not None and re.search(r"\bOK \d+", verdicts.group(1)), last
    assert "UNKNOWN_ID" not in verdicts.group(1), last  # the vendor IDs are known


def test_the_monitor_decodes_a_cia408_valve_listen_only() -> None:
    channel = "monitor-cia408"
    cfg = load_controller_config(ROOT / "configs" / "controller-cia408.yaml")
    codec = monitor_codec(cfg, ROOT / "configs" / "controller-cia408.yaml")
    assert isinstance(codec, ListenCia408Codec)
    state = MonitorState(choice_names(codec), None)
    heard = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    with Cia408Rig({"interface": "virtual", "receive_own_messages": False, "channel": channel}) as r:
        try:
            for n in (r.valve, r.encoder):
                n.nmt.state = "OPERATIONAL"
                assert heartbeat_state(n, "OPERATIONAL") == "OPERATIONAL"
                n.tpdo.read(from_od=True)
            r.valve.rpdo.read(from_od=True)
            setpoint = SCALE_100_PERCENT // 5  # +20 %
            for word in (0x0001, 0x0003, 0x0007):  # DISABLED, HOLD, ACTIVE
                r.valve.rpdo[1][0].raw = word
                r.valve.rpdo[1][1].raw = setpoint
                r.valve.rpdo[1].transmit()
                r.net.sync.transmit()
            assert wait_until(lambda: r.proc.valve.device.state.name == "ACTIVE")
            k0 = r.emu.k
            assert wait_until(lambda: r.emu.k > k0 + 100)  # the spool settles
            for _ in range(3):
                r.valve.rpdo[1].transmit()
                r.valve.tpdo[1].is_received = False
                r.net.sync.transmit()
                assert wait_until(lambda: r.valve.tpdo[1].is_received)
            time.sleep(0.05)
            decoded = []
            while (msg := heard.recv(0.0)) is not None:  # every frame sent so far, queued
                d = codec.classify(msg)
                state.feed(d, msg.dlc, time.time())
                decoded.append(d)
        finally:
            heard.shutdown()
    by_name = {d.name: d for d in decoded if d.verdict is Verdict.OK and d.values}
    current = setpoint / SCALE_100_PERCENT * cfg.nodes.full_scale_current_a
    assert by_name["VALVE_CMD"].values == {
        "CurrentSetpoint": pytest.approx(current),
        "Enable": 1,
        "ControlWord": 7,
    }
    aux = by_name["SENSOR_AUX"].values
    assert aux is not None and aux["CoilCurrent"] == pytest.approx(current)  # the set-point heard
    assert aux["Spool"] > 0.0  # +20 % moved the spool the expected way
    assert by_name["SENSOR_POS"].values is not None
    st = state.status(time.time())
    assert st["values"]["i_cmd_a"] == pytest.approx(current) and st["values"]["i_applied_a"] == pytest.approx(
        current
    )
