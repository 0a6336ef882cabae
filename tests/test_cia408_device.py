"""The emulated nodes stepped period by period (no thread, no clock): the CiA 408 device state
machine, heartbeat and timeouts counted in plant time, PDOs on SYNC, NMT."""

from __future__ import annotations

import struct
from collections.abc import Iterator

import can
import pytest

from ehpss_hil.config import Cia408Config
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.check import check_nodes
from ehpss_hil.protocol.cia408.objects import DeviceState, NmtCommand, NmtState
from ehpss_hil.runtime.rawio import RawFrameIO
from ehpss_hil.scenario import Scenario
from firmware_sim.canopen_node.device import FAULT_REACTION_S, INIT_S, NOT_READY_S, ValveStateMachine
from firmware_sim.canopen_process import CanopenEmulatorProcess, CanopenOptions, build_nodes


def test_state_machine_powers_up_through_not_ready_and_init() -> None:
    """NOT_READY (status 0x0000) then INIT (0x0008) on the loop's clock; a control word met
    there is not obeyed until DISABLED, where its request takes effect at once."""
    sm = ValveStateMachine()
    sm.power_on(1.0)
    assert (sm.state, sm.status_word) == (DeviceState.NOT_READY, 0x0000)
    assert sm.command(0x0007) is False and sm.state == DeviceState.NOT_READY
    sm.tick(1.0 + NOT_READY_S - 0.001)
    assert sm.state == DeviceState.NOT_READY
    sm.tick(1.0 + NOT_READY_S)
    assert (sm.state, sm.status_word) == (DeviceState.INIT, 0x0008)
    sm.tick(1.0 + NOT_READY_S + INIT_S)
    assert (sm.state, sm.status_word) == (DeviceState.ACTIVE, 0x000F)  # the stored request
    late = ValveStateMachine()
    late.power_on(0.0)
    late.tick(1.0)  # a loop that slept: both steps at once, to DISABLED with no request
    assert late.state == DeviceState.DISABLED and late.transitions == 2


def test_state_machine_follows_the_control_word_and_latches_faults() -> None:
    sm = ValveStateMachine()
    sm.power_on()
    sm.tick(NOT_READY_S + INIT_S)
    steps = [
        (0x0001, DeviceState.DISABLED, 0x0009),
        (0x0003, DeviceState.HOLD, 0x000B),
        (0x0007, DeviceState.ACTIVE, 0x000F),
        (0x0005, DeviceState.DISABLED, 0x0009),  # M without H: not a HOLD/ACTIVE request
        (0x0007, DeviceState.ACTIVE, 0x000F),
    ]
    for word, state, status in steps:
        sm.command(word)
        assert (sm.state, sm.status_word) == (state, status)
    assert sm.fault(0x8130, hold=True) and sm.status_word == 0x0007  # FAULT_REACTION, R clear
    assert sm.command(0x0008) is False  # no reset while the reaction runs
    sm.tick(NOT_READY_S + INIT_S + FAULT_REACTION_S)
    assert (sm.state, sm.status_word) == (DeviceState.FAULT_HOLD, 0x0003)
    sm.command(0x0000)
    assert not sm.fault(0x5000, hold=False) and sm.fault_code == 0x8130  # the first fault stays
    sm.command(0x000F)  # R rises: reset → DISABLED
    assert (sm.state, sm.fault_code) == (DeviceState.DISABLED, 0)
    sm.fault(0x5000, hold=False)
    sm.tick(1.0)
    assert sm.status_word == 0x0001
    assert sm.command(0x000F) is False  # R held high: no rising edge
    assert sm.command(0x0000) is False and sm.command(0x0008) is True
    assert sm.state == DeviceState.DISABLED


#: periods (1 kHz) until the valve's power-on states are over
POWER_ON_PERIODS = round((NOT_READY_S + INIT_S) * 1000)


class Stepper:
    """The emulator process and a peer on one virtual bus; the test steps the periods."""

    def __init__(self, channel: str, cfg: Cia408Config) -> None:
        self.cfg = cfg
        params = load_params()
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.peer = can.Bus(interface="virtual", channel=channel)
        io = RawFrameIO(self.bus)
        v_od, e_od = check_nodes(cfg, "test")
        valve, enc = build_nodes(cfg, v_od, e_od, io, params.plant.spool_stroke_m)
        self.proc = CanopenEmulatorProcess(
            PlantEmulation(params, Scenario(name="s", duration_s=100.0)), io, valve, enc, CanopenOptions(1000)
        )
        self.proc.boot()

    def send(self, can_id: int, data: bytes) -> None:
        self.peer.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.proc.step_period()

    def frames(self) -> Iterator[can.Message]:
        while (m := self.peer.recv(0.0)) is not None:
            yield m

    def close(self) -> None:
        self.bus.shutdown()
        self.peer.shutdown()


@pytest.fixture
def stepper(request: pytest.FixtureRequest) -> Iterator[Stepper]:
    s = Stepper(f"step-{request.node.name}", Cia408Config(setpoint_timeout_ms=20))
    s.step(POWER_ON_PERIODS)  # the valve's NOT_READY and INIT (no heartbeat due yet)
    yield s
    s.close()


def test_heartbeats_every_100_periods_and_tpdos_per_sync_only_when_operational(stepper: Stepper) -> None:
    v, e = stepper.cfg.valve_node, stepper.cfg.encoder_node
    boot = [(m.arbitration_id, bytes(m.data)) for m in stepper.frames()]
    assert boot == [(cobid.HEARTBEAT + v, b"\x00"), (cobid.HEARTBEAT + e, b"\x00")]
    stepper.send(cobid.SYNC, b"")
    stepper.step(1001)  # t = 0 … 1 s at 1 kHz: heartbeats at 0.1 … 1.0 s
    got = [m.arbitration_id for m in stepper.frames()]
    assert got.count(cobid.HEARTBEAT + v) == 10 and got.count(cobid.HEARTBEAT + e) == 10
    assert cobid.TPDO1 + v not in got  # PRE-OPERATIONAL: no PDO
    stepper.send(cobid.NMT, bytes([NmtCommand.START, 0]))  # all nodes
    stepper.send(cobid.SYNC, b"")
    stepper.send(cobid.SYNC, b"")
    stepper.step()
    tpdo = [(m.arbitration_id, bytes(m.data)) for m in stepper.frames() if m.arbitration_id & 0x780 == 0x180]
    assert tpdo == [(0x180 + v, b"\x09\x00\x00\x00"), (0x180 + e, b"\x00" * 4)] * 2  # DISABLED, at rest
    stepper.send(cobid.NMT, bytes([NmtCommand.STOP, v]))
    stepper.send(cobid.SYNC, b"")
    stepper.step(100)
    got2 = [(m.arbitration_id, bytes(m.data)) for m in stepper.frames()]
    assert (cobid.HEARTBEAT + v, bytes([NmtState.STOPPED])) in got2
    assert [i for i, _ in got2 if i & 0x780 == 0x180] == [0x180 + e]


def test_setpoint_timeout_is_counted_in_plant_periods(stepper: Stepper) -> None:
    v = stepper.cfg.valve_node
    stepper.send(cobid.NMT, bytes([NmtCommand.START, v]))
    stepper.step()
    stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 1638))  # ACTIVE, +10 %
    stepper.step()
    valve = stepper.proc.valve
    assert valve.device.state == DeviceState.ACTIVE
    assert valve.current_a() == pytest.approx(1638 / 16384 * stepper.cfg.full_scale_current_a)
    k_seen = stepper.proc.emu.k - 1  # the RPDO was handled in the period just stepped
    stepper.step(19)
    assert valve.device.state == DeviceState.ACTIVE  # 20 ms event timer not exceeded yet
    while valve.device.state == DeviceState.ACTIVE:
        stepper.step()
    assert stepper.proc.emu.k - 1 - k_seen == 21  # > 20 ms after the last RPDO
    assert valve.device.state == DeviceState.FAULT_REACTION and valve.current_a() == 0.0
    stepper.step(round(FAULT_REACTION_S * 1000))
    assert valve.device.state == DeviceState.FAULT_HOLD and valve.current_a() == 0.0
    emcy = [bytes(m.data) for m in stepper.frames() if m.arbitration_id == cobid.EMCY + v]
    assert emcy == [struct.pack("<HB5x", 0x8250, 0x11)]


def test_reset_communication_keeps_the_device_state_and_restores_comm_objects(stepper: Stepper) -> None:
    v = stepper.cfg.valve_node
    valve = stepper.proc.valve
    valve.store.set(0x1017, 0, 7)
    stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0003, 0))  # PRE-OPERATIONAL: RPDO ignored
    stepper.step()
    assert valve.device.state == DeviceState.DISABLED and valve.rpdos == 0
    stepper.send(cobid.SDO_RX + v, bytes([0x2B, 0x40, 0x60, 0x00, 0x03, 0x00, 0, 0]))  # 0x6040 := 3
    stepper.step()
    assert valve.device.state == DeviceState.HOLD
    stepper.send(cobid.NMT, bytes([NmtCommand.RESET_COMMUNICATION, v]))
    stepper.step()
    assert valve.store.get(0x1017) == stepper.cfg.heartbeat_time_ms and valve.device.state == DeviceState.HOLD
    stepper.send(cobid.NMT, bytes([NmtCommand.RESET_NODE, v]))
    stepper.step()
    assert valve.device.state == DeviceState.NOT_READY and valve.nmt == NmtState.PRE_OPERATIONAL
    stepper.step(POWER_ON_PERIODS)
    assert valve.device.state == DeviceState.DISABLED
    boots = [
        m for m in stepper.frames() if m.arbitration_id == cobid.HEARTBEAT + v and bytes(m.data) == b"\x00"
    ]
    assert len(boots) == 3  # power-on, reset communication, reset node


def _activate(s: Stepper) -> None:
    """NMT start of the valve, then an RPDO asking for ACTIVE at +10 %."""
    v = s.cfg.valve_node
    s.send(cobid.NMT, bytes([NmtCommand.START, v]))
    s.step()
    s.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 1638))
    s.step()
    assert s.proc.valve.device.state == DeviceState.ACTIVE and s.proc.valve.current_a() > 0.0


def _emcy(s: Stepper) -> list[bytes]:
    return [bytes(m.data) for m in s.frames() if m.arbitration_id == cobid.EMCY + s.cfg.valve_node]


def test_nmt_stop_while_active_is_the_fault_reaction_and_no_rpdo_gets_through(stepper: Stepper) -> None:
    """Another node's NMT Stop: the valve goes to FAULT_HOLD (0 A), no EMCY in STOPPED (the
    error register holds 0x11), and an RPDO asking for ACTIVE at +100 % changes nothing."""
    v, valve = stepper.cfg.valve_node, stepper.proc.valve
    _activate(stepper)
    list(stepper.frames())
    stepper.send(cobid.NMT, bytes([NmtCommand.STOP, v]))
    stepper.step()
    assert (valve.nmt, valve.device.state) == (NmtState.STOPPED, DeviceState.FAULT_REACTION)
    assert valve.current_a() == 0.0 and valve.device.fault_code == 0x8100
    assert int(valve.store.get(0x1001, 0)) == 0x11 and _emcy(stepper) == []
    for _ in range(50):
        stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 16384))
        stepper.step()
    assert valve.device.state == DeviceState.FAULT_HOLD and valve.current_a() == 0.0
    assert int(valve.store.get(0x6300, 1)) == 1638  # not even stored
    assert valve._rpdo_late == {0x1400}  # the event timer ran on in STOPPED and elapsed


def test_error_behaviour_takes_the_node_to_stopped_on_a_communication_error(stepper: Stepper) -> None:
    """0x1029.1 = 2: the set-point RPDO's timeout (a communication error) also stops the node
    (CiA 301), so a late rogue RPDO is not processed; default 1 (no change) keeps it OPERATIONAL."""
    valve = stepper.proc.valve
    assert int(valve.store.get(0x1029, 1)) == 1
    valve.store.set(0x1029, 1, 2)
    _activate(stepper)
    stepper.step(25)
    assert (valve.device.state, valve.nmt) == (DeviceState.FAULT_HOLD, NmtState.STOPPED)
    assert struct.pack("<HB5x", 0x8250, 0x11) in _emcy(stepper)  # sent before the NMT change


def test_a_short_rpdo_is_not_processed_and_reported_once(stepper: Stepper) -> None:
    v, valve = stepper.cfg.valve_node, stepper.proc.valve
    _activate(stepper)
    list(stepper.frames())
    for _ in range(5):
        stepper.send(cobid.RPDO1 + v, struct.pack("<H", 0x0001))  # 2 bytes of 4 mapped
        stepper.step()
    assert _emcy(stepper) == [struct.pack("<HB5x", 0x8210, 0x11)]
    assert valve.bad_length_frames == 5 and int(valve.store.get(0x6300, 1)) == 1638


def test_a_sync_with_data_is_not_answered_and_reported_once(stepper: Stepper) -> None:
    v, e = stepper.cfg.valve_node, stepper.cfg.encoder_node
    stepper.send(cobid.NMT, bytes([NmtCommand.START, 0]))
    stepper.step()
    list(stepper.frames())
    for _ in range(3):
        stepper.send(cobid.SYNC, b"\x01")
        stepper.step()
    got = [(m.arbitration_id, bytes(m.data)) for m in stepper.frames()]
    assert not [i for i, _ in got if i & 0x780 == 0x180]  # no TPDO answered it
    assert got.count((cobid.EMCY + v, struct.pack("<HB5x", 0x8240, 0x11))) == 1
    assert got.count((cobid.EMCY + e, struct.pack("<HB5x", 0x8240, 0x11))) == 1
    assert stepper.proc.syncs == 0


def test_the_setpoint_path_limits_ramps_and_holds(stepper: Stepper) -> None:
    """Limits clip the set-point (status word bit 10), a linear ramp of 100 ms per 100 % moves
    the demand 0x6311.1 by 163.84 a period, the hold set-point drives the valve in HOLD; the
    objects written by SDO (0x2B/0x2F expedited downloads), as a master would."""
    v, valve = stepper.cfg.valve_node, stepper.proc.valve

    def sdo(index: int, sub: int, value: int, size: int = 2) -> None:
        cmd = {1: 0x2F, 2: 0x2B}[size]
        stepper.send(
            cobid.SDO_RX + v, struct.pack("<BHB", cmd, index, sub) + value.to_bytes(4, "little", signed=True)
        )

    sdo(0x6320, 1, 8192)  # upper limit +50 %
    sdo(0x6314, 1, -1638)  # hold set-point −10 %
    stepper.step()
    _activate(stepper)  # +10 %: inside the limits
    assert valve.status_word() == 0x000F and int(valve.store.get(0x6311, 1)) == 1638
    stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 16384))
    stepper.step()
    assert valve.status_word() == 0x040F and int(valve.store.get(0x6311, 1)) == 8192  # clipped
    assert valve.current_a() == pytest.approx(0.5 * stepper.cfg.full_scale_current_a)
    stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0003, 0))  # HOLD
    stepper.step()
    assert int(valve.store.get(0x6311, 1)) == -1638 and valve.status_word() == 0x000B
    stepper.send(cobid.NMT, bytes([NmtCommand.ENTER_PRE_OPERATIONAL, v]))  # SDO while not enabled
    stepper.step()
    stepper.send(cobid.NMT, bytes([NmtCommand.START, v]))
    sdo(0x6330, 0, 1, size=1)  # linear ramp
    sdo(0x6331, 1, 100)  # 100 ms per 100 %
    stepper.step()
    stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0008, 0))  # the fault (left OPERATIONAL) reset
    stepper.step()
    stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 4096))  # +25 % from 0
    stepper.step()
    assert valve.device.state == DeviceState.ACTIVE
    for n in range(2, 6):
        stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 4096))
        stepper.step()
        assert int(valve.store.get(0x6311, 1)) == round(min(4096, n * 163.84)), n
    for _ in range(30):
        stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 4096))
        stepper.step()
    assert int(valve.store.get(0x6311, 1)) == 4096


def test_the_valves_own_spool_loop_and_its_deviation_monitoring(stepper: Stepper) -> None:
    """Device control mode 2: the set-point is a spool position and the valve's PI drives the
    spool there (+50 %: within 1 % after 40 periods); the deviation monitoring (threshold 500,
    delay 1 ms) sets status bit 11 during the step and clears it once the spool is there."""
    v, valve = stepper.cfg.valve_node, stepper.proc.valve

    def sdo(index: int, value: int, size: int) -> None:
        cmd = {1: 0x2F, 2: 0x2B}[size]
        stepper.send(cobid.SDO_RX + v, struct.pack("<BHB", cmd, index, 0) + value.to_bytes(4, "little"))

    for index, value, size in ((0x6043, 2, 1), (0x6351, 1, 1), (0x6352, 1, 2), (0x6353, 500, 2)):
        sdo(index, value, size)
    stepper.step()
    assert valve.closed_loop
    _activate(stepper)
    words = []
    for _ in range(40):
        stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 8192))
        stepper.step()
        words.append(valve.status_word())
    assert any(w & 0x0800 for w in words[:20]) and not words[-1] & 0x0800
    assert abs(valve.spool_actual - 8192) < 164 and abs(valve.deviation()) < 164
    assert 0.0 < valve.current_a() < stepper.cfg.full_scale_current_a
    stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0001, 0))  # DISABLED: no current
    stepper.step()
    assert valve.current_a() == 0.0


def test_the_monitoring_window_is_one_sided(stepper: Stepper) -> None:
    """Type 2 in the valve's own spool loop: during a +50 % step the deviation is positive, so a
    window [−16384, 500] alarms (bit 11) while one of [−500, 16384] does not."""
    v, valve = stepper.cfg.valve_node, stepper.proc.valve

    def sdo(index: int, value: int, size: int) -> None:
        cmd = {1: 0x2F, 2: 0x2B}[size]
        data = (value & 0xFFFF_FFFF).to_bytes(4, "little")
        stepper.send(cobid.SDO_RX + v, struct.pack("<BHB", cmd, index, 0) + data)
        stepper.step()

    for index, value, size in ((0x6043, 2, 1), (0x6351, 2, 1), (0x6352, 1, 2)):
        sdo(index, value, size)
    sdo(0x6354, 16384, 2)
    sdo(0x6355, -500, 2)
    _activate(stepper)

    def step_to(setpoint: int) -> list[int]:
        words = []
        for _ in range(40):
            stepper.send(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, setpoint))
            stepper.step()
            words.append(valve.status_word())
        return words

    assert not any(w & 0x0800 for w in step_to(8192))  # deviation > 0 inside [−500, 16384]
    assert abs(valve.deviation()) < 164
    sdo(0x6354, 500, 2)
    sdo(0x6355, -16384, 2)
    assert valve.monitoring_band() == (-16384, 500)
    assert not step_to(-8192)[-1] & 0x0800  # a negative step stays inside [−16384, 500]
    words = step_to(8192)
    assert any(w & 0x0800 for w in words[:20]) and not words[-1] & 0x0800
