"""The master's part of each cycle (:class:`~ehpss_hil.protocol.cia408.master.CyclicMaster`) fed
real frames — the emulated valve's own TPDOs and EMCY, heartbeat frames — and stepped by hand:
which fail-safe reason each failure gives, and the control word it leaves."""

from __future__ import annotations

import can
import pytest
from test_cia408_cyclic import CFG, STROKE_M, Nodes

from ehpss_hil.config import CanIds
from ehpss_hil.protocol import make_codec
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.codec import Cia408Codec
from ehpss_hil.protocol.cia408.master import CyclicMaster
from ehpss_hil.protocol.cia408.objects import BIT_D, NmtState
from ehpss_hil.protocol.failsafe import FailsafeReason

RATE_HZ = 1000.0


class Rig:
    """Nodes, the master's codec and its cycle; :meth:`cycle` is one loop cycle."""

    def __init__(self) -> None:
        self.nodes = Nodes()
        codec = make_codec("cia408", "", CanIds(), "test", None, CFG, STROKE_M)
        assert isinstance(codec, Cia408Codec)
        self.codec = codec
        self.master = CyclicMaster(codec, CFG, RATE_HZ)
        self.cycles = 0

    def heartbeat(self, node: int, state: int = NmtState.OPERATIONAL) -> None:
        self.master.on_frame(can.Message(arbitration_id=cobid.HEARTBEAT + node, data=bytes([state])))

    def cycle(self, heartbeats: bool = True, tpdos: bool = True) -> FailsafeReason | None:
        """Drain (the valve's TPDO, EMCY, heartbeats), update, command, SYNC."""
        sent, self.nodes.sent = self.nodes.sent, []
        for msg in [*sent, *(self.nodes.sync() if tpdos else [])]:
            if msg.arbitration_id == self.codec.can_id("SENSOR_AUX"):
                self.codec.classify(msg)
            else:
                self.master.on_frame(msg)
        if heartbeats:
            for node in (CFG.valve_node, CFG.encoder_node):
                self.heartbeat(node)
        reason = self.master.update(self.cycles)
        self.nodes.deliver(self.codec.encode("VALVE_CMD", {"CurrentSetpoint": 1e-4, "Enable": 1}))
        self.cycles += 1
        return reason

    def run_until_ready(self) -> None:
        for _ in range(10):
            self.cycle()
        assert self.master.ready and self.master.reason is None


def test_ready_only_once_the_valve_is_active() -> None:
    rig = Rig()
    assert rig.cycle() is None and not rig.master.ready  # DISABLED → HOLD asked for
    rig.run_until_ready()
    assert rig.nodes.valve.current_a() == pytest.approx(1e-4, abs=CFG.full_scale_current_a / 16384)


def test_an_emcy_is_the_reason_with_its_code_and_disables_the_valve() -> None:
    rig = Rig()
    rig.run_until_ready()
    rig.nodes.valve.inject_fault(0x5000)
    assert rig.cycle() is FailsafeReason.EMCY  # the EMCY comes before the status word is checked
    assert rig.master.emcy == (CFG.valve_node, 0x5000, 1) and rig.master.fault_cycle == rig.cycles - 1
    assert rig.codec.control_word == BIT_D and not rig.master.ready
    assert rig.master.device_values() == {
        "EmcyNode": CFG.valve_node,
        "EmcyCode": 0x5000,
        "ErrorRegister": 1,
        "StatusWord": 0x0007,  # FAULT_REACTION: D+H+M with R (ready) clear
    }
    assert rig.cycle() is FailsafeReason.EMCY  # latched: the status word leaving ACTIVE adds nothing


def test_an_error_reset_emcy_is_no_fault() -> None:
    rig = Rig()
    rig.run_until_ready()
    rig.master.on_frame(can.Message(arbitration_id=cobid.EMCY + CFG.valve_node, data=bytes(8)))
    assert rig.cycle() is None and rig.master.emcy_frames == 0


def test_status_word_leaving_active_is_a_device_fault() -> None:
    rig = Rig()
    rig.run_until_ready()
    rig.nodes.valve.device.command(0x0003)  # the valve drops to HOLD on its own (no EMCY)
    assert rig.cycle() is FailsafeReason.DEVICE_FAULT
    assert "HOLD" in rig.master.fault_text and rig.codec.control_word == BIT_D


def test_heartbeat_loss_and_a_node_leaving_operational() -> None:
    rig = Rig()
    rig.run_until_ready()
    limit = rig.master.hb_timeout_cycles
    assert limit == 300  # node_heartbeat_timeout_ms 300 at 1 kHz
    reasons = [rig.cycle(heartbeats=False) for _ in range(limit + 1)]
    assert reasons[:limit] == [None] * limit and reasons[-1] is FailsafeReason.HEARTBEAT_LOST
    rig = Rig()
    rig.run_until_ready()
    rig.heartbeat(CFG.encoder_node, NmtState.STOPPED)
    assert rig.cycle(heartbeats=False) is FailsafeReason.HEARTBEAT_LOST
    assert "STOPPED" in rig.master.fault_text


def test_cycles_without_the_status_word_are_not_fresh_for_the_watchdog() -> None:
    rig = Rig()
    rig.run_until_ready()
    assert rig.master.status_fresh
    assert rig.cycle(tpdos=False) is None and rig.master.status_fresh  # the one before counts
    assert rig.cycle(tpdos=False) is None and not rig.master.status_fresh
    assert rig.cycle() is None and rig.master.status_fresh and rig.master.ready


def test_an_emcy_before_the_valve_was_active_is_reset_not_latched() -> None:
    rig = Rig()
    rig.nodes.valve.on_heartbeat_lost(CFG.master_node)  # our heartbeat missed during start-up
    assert rig.cycle() is None and rig.master.emcy == (CFG.valve_node, 0x8130, 0x11)
    for _ in range(6):
        rig.cycle()
    assert rig.master.ready and rig.master.drive.fault_resets == 1


def test_no_heartbeat_watch_when_the_start_up_turns_heartbeats_off() -> None:
    from dataclasses import replace

    rig = Rig()
    rig.master = CyclicMaster(rig.codec, replace(CFG, heartbeat_time_ms=0), RATE_HZ)
    reasons = [rig.cycle(heartbeats=False) for _ in range(rig.master.hb_timeout_cycles + 5)]
    assert set(reasons) == {None} and rig.master.ready
