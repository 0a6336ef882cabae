"""The master's cyclic side of ``protocol: cia408`` against the emulator's own node classes
(stepped by hand, no bus, no clock): the set-point RPDO the valve applies, the TPDOs the codec
decodes, the device state machine driven through the control word, EMCY and heartbeat frames."""

from __future__ import annotations

from typing import Any

import can
import pytest

from ehpss_hil.codec import Verdict
from ehpss_hil.config import CanIds, Cia408Config, ControllerConfig
from ehpss_hil.errors import ConfigError
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol import make_codec
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.check import check_nodes
from ehpss_hil.protocol.cia408.codec import Cia408Codec
from ehpss_hil.protocol.cia408.cyclic import Scaling, unpack_emcy, unpack_heartbeat
from ehpss_hil.protocol.cia408.drive import MAX_FAULT_RESETS, REQUEST, DeviceDrive
from ehpss_hil.protocol.cia408.objects import BIT_R, DeviceState, NmtCommand, NmtState
from firmware_sim.canopen_node.device import INIT_S, NOT_READY_S
from firmware_sim.canopen_node.encoder import EncoderNode
from firmware_sim.canopen_node.valve import ValveNode

CFG = Cia408Config()
STROKE_M = load_params().plant.spool_stroke_m
#: the loop period the nodes' clock advances by per SYNC (s)
TS_S = 0.001


class Nodes:
    """The emulated valve and encoder, OPERATIONAL, their frames collected as python-can frames."""

    def __init__(self) -> None:
        self.sent: list[can.Message] = []
        v_od, e_od = check_nodes(CFG, "test")
        self.valve = ValveNode(CFG.valve_node, v_od, self._send, CFG.full_scale_current_a, STROKE_M)
        self.encoder = EncoderNode(CFG.encoder_node, e_od, self._send)
        for n in (self.valve, self.encoder):
            n.boot(0.0)
            n.on_frame(cobid.NMT, bytes([NmtCommand.START, 0]), 0.0)
        #: loop time (s): a SYNC a period; the valve's power-on states are over
        self.t_s = NOT_READY_S + INIT_S
        self.valve.device.tick(self.t_s)
        self.sent.clear()

    def _send(self, can_id: int, data: bytes) -> None:
        self.sent.append(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def deliver(self, msg: can.Message) -> None:
        for n in (self.valve, self.encoder):
            n.on_frame(msg.arbitration_id, bytes(msg.data), 0.0)

    def sync(self) -> list[can.Message]:
        """A SYNC: the TPDOs it makes the nodes send, in order."""
        self.sent.clear()
        self.t_s += TS_S
        self.valve.device.tick(self.t_s)  # a fault reaction ends
        for n in (self.valve, self.encoder):
            n.on_sync()
        out, self.sent = self.sent, []
        return out


@pytest.fixture
def codec() -> Cia408Codec:
    c = make_codec("cia408", "", CanIds(), "test", None, CFG, STROKE_M)
    assert isinstance(c, Cia408Codec)
    return c


def _enable(nodes: Nodes, codec: Cia408Codec, drive: DeviceDrive, cycles: int = 10) -> list[int]:
    """Cycles of: the valve's TPDO → drive → VALVE_CMD at 0 A; the control words sent."""
    words = []
    for _ in range(cycles):
        valve_tpdo, _ = nodes.sync()
        codec.classify(valve_tpdo)
        codec.control_word = drive.update(codec.status_word)
        words.append(codec.control_word)
        nodes.deliver(codec.encode("VALVE_CMD", {"CurrentSetpoint": 0.0, "Enable": 1}))
    return words


def test_scaling_rounds_and_clips_the_setpoint() -> None:
    sc = Scaling(0.001, 0.01, 1e-7)
    assert sc.setpoint_raw(0.0005) == 8192 and sc.setpoint_raw(-0.00025) == -4096
    assert sc.setpoint_raw(0.002) == 16384 and sc.setpoint_raw(-1.0) == -16384  # ±100 %
    assert sc.current_a(8192) == pytest.approx(0.0005)
    assert sc.spool_raw(0.005) == 8192 and sc.spool_m(-16384) == pytest.approx(-0.01)
    assert sc.position_raw(0.0123456) == 123456


def test_drive_walks_disabled_hold_active_and_the_valve_applies_the_setpoint(codec: Cia408Codec) -> None:
    nodes, drive = Nodes(), DeviceDrive()
    words = _enable(nodes, codec, drive)
    # the valve shows DISABLED after power-on: HOLD is asked for, then ACTIVE once HOLD shows
    assert words[:3] == [0x0003, 0x0007, 0x0007]
    assert nodes.valve.device.state is DeviceState.ACTIVE and drive.active and drive.was_active
    codec.encode("VALVE_CMD", {"CurrentSetpoint": 3e-4, "Enable": 1})  # a command the valve never got
    nodes.deliver(codec.encode("VALVE_CMD", {"CurrentSetpoint": 2.5e-4, "Enable": 1}))
    assert nodes.valve.current_a() == pytest.approx(4096 / 16384 * CFG.full_scale_current_a)
    nodes.deliver(codec.encode("VALVE_CMD", {"CurrentSetpoint": 2.5e-4, "Enable": 0}))
    assert nodes.valve.current_a() == 0.0  # Enable 0: set-point 0


def test_tpdos_decode_to_position_spool_and_the_echo_of_the_command_two_back(codec: Cia408Codec) -> None:
    nodes, drive = Nodes(), DeviceDrive()
    _enable(nodes, codec, drive)
    for amps in (1e-4, 2e-4):
        codec.encode("VALVE_CMD", {"CurrentSetpoint": amps, "Enable": 1})
    nodes.valve.measure(-0.0031)
    nodes.encoder.measure(0.0123456)
    valve_tpdo, encoder_tpdo = nodes.sync()
    assert (valve_tpdo.arbitration_id, encoder_tpdo.arbitration_id) == (0x1A0, 0x1A1)
    aux, pos = codec.classify(valve_tpdo), codec.classify(encoder_tpdo)
    assert (aux.verdict, aux.name, pos.verdict, pos.name) == (
        Verdict.OK,
        "SENSOR_AUX",
        Verdict.OK,
        "SENSOR_POS",
    )
    assert aux.values is not None and pos.values is not None
    spool = round(-0.0031 / STROKE_M * 16384) * STROKE_M / 16384
    assert pos.values["Position"] == pytest.approx(0.0123456, abs=1e-12)
    assert pos.values["Spool"] == pytest.approx(spool) and aux.values["Spool"] == pos.values["Spool"]
    assert aux.values["CoilCurrent"] == pytest.approx(
        round(1e-4 / CFG.full_scale_current_a * 16384) * 0.001 / 16384
    )
    assert aux.values["LoadPressure"] == 0.0 and aux.values["StatusWord"] == 0x000F
    second = codec.classify(nodes.sync()[1])
    assert second.counter == (pos.counter or 0) + 1  # the codec numbers the encoder TPDOs


def test_status_leaving_active_trips_the_drive_and_disables(codec: Cia408Codec) -> None:
    nodes, drive = Nodes(), DeviceDrive()
    _enable(nodes, codec, drive)
    nodes.valve.inject_fault(0x5000)
    emcy = nodes.sent[-1]
    assert emcy.arbitration_id == cobid.EMCY + CFG.valve_node and unpack_emcy(bytes(emcy.data)) == (0x5000, 1)
    words = _enable(nodes, codec, drive, cycles=3)
    # the first status word after it shows the fault reaction; no reset: DISABLED
    assert drive.left_active is DeviceState.FAULT_REACTION and words == [0x0001] * 3
    assert not drive.active and nodes.valve.device.state is DeviceState.FAULT


def test_a_fault_met_while_enabling_is_reset_on_a_rising_edge(codec: Cia408Codec) -> None:
    nodes, drive = Nodes(), DeviceDrive()
    nodes.valve.inject_fault(0x5000)
    words = _enable(nodes, codec, drive, cycles=8)
    edge = words.index(0x0001 | BIT_R)  # after the fault reaction (no reset while it runs)
    assert words[:edge] == [0x0001] * edge and edge <= 3
    assert not any(w & BIT_R for w in words[edge + 1 :])  # one rising edge
    assert words[edge + 1 : edge + 3] == [0x0003, 0x0007]  # DISABLED after it: enabling again
    assert nodes.valve.device.state is DeviceState.ACTIVE and drive.fault_resets == 1
    assert drive.left_active is None


def test_the_drive_gives_up_after_its_resets() -> None:
    drive = DeviceDrive()
    words = [drive.update(0x0001) for _ in range(200)][-1:]  # FAULT shows D with R clear
    assert (
        drive.gave_up and drive.fault_resets == MAX_FAULT_RESETS and words == [REQUEST[DeviceState.DISABLED]]
    )


def test_malformed_and_implausible_pdos_are_not_used(codec: Cia408Codec) -> None:
    short = can.Message(arbitration_id=0x1A1, data=b"\x00\x00\x00", is_extended_id=False)
    assert codec.classify(short).verdict is Verdict.BAD_DLC
    far = codec.encode("SENSOR_POS", {"Position": 0.0})
    far.data = bytearray((10**7).to_bytes(4, "little", signed=True))  # 1 m: outside ±0.5 m
    assert codec.classify(far).verdict is Verdict.OUT_OF_RANGE
    assert codec.counts_by_name["SENSOR_POS"][Verdict.BAD_DLC] == 1


def test_heartbeat_states() -> None:
    assert unpack_heartbeat(bytes([0x05])) is NmtState.OPERATIONAL
    assert unpack_heartbeat(bytes([0x85])) is NmtState.OPERATIONAL  # the toggle bit masked
    assert unpack_heartbeat(bytes([0x05, 0])) is None and unpack_heartbeat(bytes([0x33])) is None


def _controller(**kw: Any) -> ControllerConfig:
    return ControllerConfig(protocol="cia408", **kw)


def test_controller_config_constraints_of_the_master() -> None:
    from ehpss_hil.control.tuning import ControlTuning

    with pytest.raises(ConfigError, match="flow_gain_test"):
        _controller()  # mmac with its k_Q test: the valve reports no load pressure
    ok = _controller(tuning=ControlTuning(flow_gain_test=False))
    assert ok.nodes.valve_node == 32
    with pytest.raises(ConfigError, match="master_node"):
        _controller(mode="nrc", cia408=Cia408Config(master_node=5))
    with pytest.raises(ConfigError, match="cia408"):
        ControllerConfig(cia408=Cia408Config())  # only read with protocol cia408
    with pytest.raises(ConfigError) as exc:
        _controller(mode="nrc", cia408=Cia408Config(heartbeat_time_ms=100, node_heartbeat_timeout_ms=100))
    assert exc.value.key_path == "cia408.node_heartbeat_timeout_ms"


def test_a_native_frame_on_a_master_cob_id_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"ids\.id_base") as exc:
        make_codec("cia408", "", CanIds(id_base=0x170), "test", None, CFG, STROKE_M)  # SETPOINT at 0x1A0
    assert "SETPOINT at 0x1A0 is the TPDO1 of node 32" in str(exc.value)


def test_the_daemon_refuses_lockstep_with_cia408_in_one_line() -> None:
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    cmd = [sys.executable, "-m", "ehpss_hil.cli", "controller", "-c", "configs/controller-cia408.yaml"]
    p = subprocess.run([*cmd, "--lockstep"], cwd=root, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and p.stderr.count("\n") == 1
    assert "protocol: cia408 runs in realtime only" in p.stderr


@pytest.mark.parametrize(
    ("changes", "key"),
    [
        ({"valve_position_object": 0x2101}, "cia408.valve_position_object"),  # not in the EDS
        ({"valve_position_object": 0x6301, "valve_position_sub": 1}, "cia408.valve_position_object"),  # INT16
        ({"valve_position_step_nm": 5000}, "cia408.valve_position_step_nm"),  # coarser than 3 µm
    ],
)
def test_a_valve_position_the_master_cannot_use_is_refused(changes: dict[str, int], key: str) -> None:
    from dataclasses import replace

    c = replace(CFG, position_source="valve", **changes)  # type: ignore[arg-type]
    with pytest.raises(ConfigError) as exc:
        make_codec("cia408", "", CanIds(), "test", None, c, STROKE_M)
    assert exc.value.key_path == key


def test_check_config_summarizes_the_master() -> None:
    from pathlib import Path

    from ehpss_hil.commands.check_config import summarize

    cfg = Path(__file__).resolve().parent.parent / "configs" / "controller-cia408.yaml"
    assert summarize(cfg).endswith(
        ", protocol cia408 master (valve node 32, position from encoder node 33, SYNC produced)"
    )
