"""The controller's loop as the CANopen master against the emulator's CANopen loop, both in this
process on one virtual bus and stepped alternately (no thread, no clock): the valve enabled
through the control word, SYNC per cycle (or another node's), tracking commands applied by the
valve, an EMCY into fail-safe, the stop sequence. The start-up by SDO is left out (the nodes
start with the EDS mappings the master would write; ``tests/test_cia408_master_processes.py``
runs it)."""

from __future__ import annotations

from collections.abc import Iterator

import can
import pytest

from ehpss_hil.codec import Verdict
from ehpss_hil.config import CanIds, Cia408Config
from ehpss_hil.control.registry import make_controller
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol import make_codec
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.check import check_nodes
from ehpss_hil.protocol.cia408.codec import Cia408Codec
from ehpss_hil.protocol.cia408.master import CyclicMaster
from ehpss_hil.protocol.cia408.objects import (
    CONTROL_WORD,
    VPOC_SETPOINT,
    VPOC_SUB,
    DeviceState,
    NmtCommand,
    NmtState,
)
from ehpss_hil.protocol.failsafe import FailsafeReason
from ehpss_hil.runtime.controller_loop import CIA408_OWN_FRAMES, OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.lifecycle import State
from ehpss_hil.runtime.loop_run import loop_summary
from ehpss_hil.runtime.rawio import RawFrameIO
from ehpss_hil.scenario import Reference, Scenario
from firmware_sim.canopen_process import CanopenEmulatorProcess, CanopenOptions, build_nodes

RATE_HZ = 1000.0


class Rig:
    """Controller loop + emulator on virtual channel ``channel``; a host bus for NMT/SYNC."""

    def __init__(self, channel: str, sync: str = "produce", position_source: str = "encoder") -> None:
        params = load_params()
        self.cfg = Cia408Config(sync=sync, position_source=position_source)  # type: ignore[arg-type]
        codec = make_codec("cia408", "", CanIds(), "test", None, self.cfg, params.plant.spool_stroke_m)
        assert isinstance(codec, Cia408Codec)
        self.codec = codec
        self.buses = [can.Bus(interface="virtual", channel=channel) for _ in range(3)]
        own = (*OWN_FRAMES, *(f for f in CIA408_OWN_FRAMES if f != "SYNC" or sync == "produce"))
        self.io = FrameIO(self.buses[0], codec, own)
        ref = Reference()
        ctrl = make_controller("nrc", params, 1.0 / RATE_HZ, None, ref)
        self.master = CyclicMaster(codec, self.cfg, RATE_HZ)
        self.loop = ControllerLoop(ctrl, self.io, ref, LoopOptions(rate_hz=RATE_HZ), self.master)
        v_od, e_od = check_nodes(self.cfg, "test")
        emu_io = RawFrameIO(self.buses[1])
        valve, enc = build_nodes(self.cfg, v_od, e_od, emu_io, params.plant.spool_stroke_m)
        emu = PlantEmulation(params, Scenario(name="loop", duration_s=100.0))
        self.proc = CanopenEmulatorProcess(emu, emu_io, valve, enc, CanopenOptions(1000))
        self.proc.boot()
        if position_source == "valve":  # what the start-up writes (0x2100 into TPDO 2)
            for sub, value in ((1, 0x2A0), (2, 1)):
                valve.store.set(0x1801, sub, value)
            valve.store.set(0x1A01, 1, 0x21000020)
            valve.store.set(0x1A01, 0, 1)
        # the start-up's NMT start, on the master's own bus (as MasterSession sends it)
        self.buses[0].send(
            can.Message(arbitration_id=cobid.NMT, data=bytes([NmtCommand.START, 0]), is_extended_id=False)
        )
        self.proc.step_period()  # NMT start taken
        for _ in self.io.drain():  # the boot-up messages: the start-up's (MasterSession) to read
            pass

    def host(self, can_id: int, data: bytes) -> None:
        self.buses[2].send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def step(self, n: int = 1, external_sync: bool = False) -> None:
        """``n`` controller cycles, each followed by one emulator period."""
        for _ in range(n):
            self.loop.poll_cycle()
            if external_sync:
                self.host(cobid.SYNC, b"")
            self.proc.step_period()

    def close(self) -> None:
        for b in self.buses:
            b.shutdown()


@pytest.fixture
def rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    r = Rig(f"loop-{request.node.name}")
    yield r
    r.close()


def _applied_setpoint(r: Rig) -> int:
    return int(r.proc.valve.store.get(VPOC_SETPOINT, VPOC_SUB))


def test_the_loop_enables_the_valve_then_steps_with_sync_per_cycle(rig: Rig) -> None:
    rig.step(8)  # the valve powers up: NOT_READY 5 ms, INIT 5 ms; the drive asks for DISABLED
    assert rig.proc.valve.device.state is DeviceState.INIT and rig.loop.life.state is State.CONFIGURED
    assert rig.codec.control_word == 0x0001
    rig.step(12)  # DISABLED, then HOLD and ACTIVE as the status word confirms each
    assert rig.proc.valve.device.state is DeviceState.ACTIVE and rig.loop.life.state is State.ACTIVE
    rig.step(200)
    sent = rig.io.sent
    assert sent["SYNC"] == sent["VALVE_CMD"] == 220 and rig.proc.syncs == 220
    assert rig.proc.valve.tpdos == rig.proc.encoder.tpdos == 220
    assert rig.loop.last_current_a != 0.0  # the sine reference moves the piston
    assert _applied_setpoint(rig) == rig.codec.scaling.setpoint_raw(rig.loop.last_current_a)
    assert rig.proc.valve.current_a() == pytest.approx(rig.codec.scaling.current_a(_applied_setpoint(rig)))
    assert rig.loop.wd.trips == 0 and rig.master.summary()["sync"] == "produced"


def test_an_emcy_puts_the_loop_into_failsafe_and_the_valve_gets_zero(rig: Rig) -> None:
    rig.step(50)
    rig.proc.valve.inject_fault(0x5000)  # sent now: the controller drains it in its next cycle
    rig.step(1)
    assert (rig.loop.life.state, rig.loop.life.reason) == (State.FAULT, FailsafeReason.EMCY)
    rig.step(1)
    assert _applied_setpoint(rig) == 0 and int(rig.proc.valve.store.get(CONTROL_WORD, 0)) == 0x0001
    assert loop_summary(rig.loop)["cia408"]["emcy"] == {"node": 32, "code": 0x5000, "register": 1}  # type: ignore[index]


def test_an_emcy_while_already_in_failsafe_becomes_the_reason(rig: Rig) -> None:
    """A starved loop is in its fail-safe (LOOP_OVERRUN) when the valve reports a fault: the
    device's diagnosis replaces the loop's, and the loop stays in FAULT while the valve is."""
    rig.step(50)
    for _ in range(20):  # the loop sleeps through 20 periods (more than it bridges), the nodes not
        rig.proc.step_period()
    rig.loop.poll_cycle(skipped=20)
    rig.proc.step_period()
    assert (rig.loop.life.state, rig.loop.life.reason) == (State.FAULT, FailsafeReason.LOOP_OVERRUN)
    rig.proc.valve.inject_fault(0x5000)
    rig.step(2)
    assert (rig.loop.life.state, rig.loop.life.reason) == (State.FAULT, FailsafeReason.EMCY)
    rig.step(200)  # fresh data again: the valve's fault still holds the loop
    assert (rig.loop.life.state, rig.loop.life.reason) == (State.FAULT, FailsafeReason.EMCY)


def test_stop_sends_zero_with_disabled(rig: Rig) -> None:
    rig.step(50)
    rig.loop.shutdown()
    rig.proc.step_period()
    assert rig.proc.valve.device.state is DeviceState.DISABLED and _applied_setpoint(rig) == 0
    assert rig.loop.life.state is State.STOPPED


def test_following_an_external_sync() -> None:
    r = Rig("loop-follow", sync="follow")
    try:
        r.step(60, external_sync=True)
        assert "SYNC" not in r.io.sent and r.proc.syncs == 60
        assert r.master.syncs_seen == 59  # the last one is still on its way to the next drain
        assert r.loop.life.state is State.ACTIVE and not any(r.io.collisions.by_name.values())
    finally:
        r.close()


def test_periods_the_loop_slept_through_count_as_sensor_samples(rig: Rig) -> None:
    """The controller stalls 2 periods (no SYNC sent) while the emulator runs on: the TPDO of
    the next SYNC stands for 3 samples (its counter is that SYNC's cycle), as the native E2E
    counter would say; numbering the TPDOs on arrival would say 1."""
    rig.step(50)
    rig.loop.poll_cycle()  # cycle 50 sends SYNC 50
    for _ in range(3):  # the emulator answers SYNC 50, then runs on without SYNCs
        rig.proc.step_period()
    rig.loop.poll_cycle(skipped=2)  # cycles 51–52 slept through; cycle 53 uses TPDO(50)
    assert rig.loop.meas.samples == 1 and rig.io.sent["SYNC"] == 52
    rig.proc.step_period()  # answers SYNC 53
    rig.loop.poll_cycle()
    assert rig.loop.meas.samples == 3 and rig.loop.skipped_periods == 2
    assert rig.loop.life.state is State.ACTIVE


def test_a_node_answering_missed_syncs_at_once_gives_one_sample(rig: Rig) -> None:
    """The emulator falls 3 SYNCs behind and answers them in one period with one sample: the
    controller steps on it once, as 3 samples after the last, not as 3 samples of one value."""
    rig.step(50)
    for _ in range(3):  # SYNCs 50, 51, 52 sent; the emulator stalls
        rig.loop.poll_cycle()
    rig.proc.step_period()  # three TPDO rounds, one sample
    assert rig.proc.encoder.tpdos == 53
    before = rig.codec.counts_by_name["SENSOR_POS"][Verdict.OK]
    rig.loop.poll_cycle()
    assert rig.codec.counts_by_name["SENSOR_POS"][Verdict.OK] == before + 3
    assert rig.loop.meas.samples == 3 and rig.loop.meas.fresh
    assert rig.loop.life.state is State.ACTIVE


def test_the_position_from_an_object_of_the_valve() -> None:
    r = Rig("loop-valve-position", position_source="valve")
    try:
        r.step(99)
        sent = r.proc.valve.position_value  # measured in the emulator's last period
        assert sent != 0  # the piston moved
        r.step(1)  # the controller's cycle 99 reads it from the valve's TPDO 2
        assert r.loop.life.state is State.ACTIVE and r.io.sent["SYNC"] == 100
        assert r.codec.counts_by_name["SENSOR_POS"][Verdict.OK] == 99
        assert r.loop.meas.position_m == pytest.approx(sent * 1e-7, abs=1e-12)
    finally:
        r.close()


@pytest.mark.parametrize(
    ("can_id", "data", "frame"),
    [
        (cobid.RPDO1 + 32, bytes.fromhex("07000040"), "VALVE_CMD"),  # ACTIVE, +100 %
        (cobid.NMT, bytes([NmtCommand.STOP, 32]), "NMT"),
        (cobid.SYNC, b"", "SYNC"),
        (cobid.RPDO1 + 32, bytes.fromhex("0700"), "VALVE_CMD"),  # shorter than mapped
    ],
    ids=["rpdo", "nmt-stop", "sync", "short-rpdo"],
)
def test_a_third_node_on_the_masters_frames_shuts_the_valve_out(
    rig: Rig, can_id: int, data: bytes, frame: str
) -> None:
    """Fail-safe ID_COLLISION in the cycle that drains the first foreign frame; the master's SDO
    DISABLED and NMT Stop reach the valve in the next period: STOPPED, no current, and the
    foreign frames after it change nothing (the heartbeat of our own Stop is no failure)."""
    rig.step(50)
    rig.host(can_id, data)
    rig.loop.poll_cycle()
    assert (rig.loop.life.state, rig.loop.life.reason) == (State.FAULT, FailsafeReason.ID_COLLISION)
    assert rig.io.sent["NMT"] == 1 and rig.io.sent["SDO"] == 1 and rig.master.shut_out
    rig.proc.step_period()
    valve = rig.proc.valve
    assert valve.nmt is NmtState.STOPPED and valve.current_a() == 0.0
    assert valve.device.state in (DeviceState.DISABLED, DeviceState.FAULT_REACTION, DeviceState.FAULT_HOLD)
    for _ in range(300):  # the rogue goes on; heartbeats of the stopped valve come in
        rig.host(can_id, data)
        rig.step()
    assert valve.current_a() == 0.0 and valve.device.state is not DeviceState.ACTIVE
    assert rig.loop.life.reason is FailsafeReason.ID_COLLISION
    assert rig.master.reason is FailsafeReason.ID_COLLISION and rig.io.sent["NMT"] == 1
    assert rig.io.collisions.by_name[frame] >= 1


def test_a_tpdo_shorter_than_mapped_is_a_pdo_error(rig: Rig) -> None:
    rig.step(50)
    rig.host(cobid.TPDO1 + 32, bytes.fromhex("0f00"))  # the valve's TPDO 1, 2 of 4 bytes
    rig.loop.poll_cycle()
    assert (rig.loop.life.state, rig.loop.life.reason) == (State.FAULT, FailsafeReason.PDO_ERROR)
    assert rig.master.summary()["bad_length_pdos"] == 1 and rig.master.shut_out
    rig.proc.step_period()
    assert rig.proc.valve.nmt is NmtState.STOPPED and rig.proc.valve.current_a() == 0.0


def test_the_master_reads_the_error_history_after_an_emcy(rig: Rig) -> None:
    """The EMCY is followed by the master's SDO reads of 0x1003.0 and 0x1003.1 (one request
    per cycle, answered by the valve's SDO server in the emulator's loop)."""
    rig.step(50)
    rig.proc.valve.inject_fault(0x5000)
    rig.step(10)
    assert rig.master.history.codes == [0x5000] and rig.master.history.reads == 1
    assert rig.master.summary()["error_history"] == {"node": 32, "codes": [0x5000]}
    assert rig.io.sent["SDO"] == 2 and not rig.master.shut_out  # the valve's own fault: no stop


def test_following_sync_a_second_producer_is_a_collision() -> None:
    """sync: follow: SYNC is another node's; a second producer doubles the SYNCs per cycle and
    within the 40-cycle window the master declares ID_COLLISION and shuts the valve out."""
    r = Rig("loop-follow-two", sync="follow")
    try:
        r.step(60, external_sync=True)
        assert r.loop.life.state is State.ACTIVE
        for _ in range(45):
            r.host(cobid.SYNC, b"")  # the second producer
            r.step(external_sync=True)
        assert (r.loop.life.state, r.loop.life.reason) == (State.FAULT, FailsafeReason.ID_COLLISION)
        assert r.master.shut_out and "second producer" in r.master.fault_text
        r.step(1, external_sync=True)
        assert r.proc.valve.nmt is NmtState.STOPPED and r.proc.valve.current_a() == 0.0
    finally:
        r.close()
