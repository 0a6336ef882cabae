"""Independent checks of the emulated CANopen nodes (issue #18 item 5): ``canopen``'s own master
(``canopen.Network``, ``RemoteNode``, its SDO client, NMT, heartbeat, PDO and EMCY consumers)
talks to firmware-sim's CiA 408 valve and CiA 406 encoder on a python-can ``virtual`` bus.
"""

from __future__ import annotations

import struct
from pathlib import Path

import canopen
import pytest
from _cia408 import Cia408Rig, emcy_codes, heartbeat_state, wait_until

from ehpss_hil.bus import af_can_available
from ehpss_hil.canlog import read_log
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.objects import (
    ABORT_LENGTH,
    ABORT_NOT_IN_OD,
    ABORT_RANGE,
    ABORT_READ_ONLY,
    ABORT_STATE,
    EMCY_HEARTBEAT,
    EMCY_NO_ERROR,
    EMCY_RPDO_TIMEOUT,
    SCALE_100_PERCENT,
    DeviceState,
    NmtState,
    state_of_status,
)
from ehpss_hil.scenario import Event, Scenario

VIRTUAL = {"interface": "virtual", "receive_own_messages": False}
#: +20 % (0.2 mA at the default 1 mA full scale: a 3.3 mm spool, inside its ±10 mm stroke)
SETPOINT = 3277


def _rig(name: str, **kw: object) -> Cia408Rig:
    return Cia408Rig({**VIRTUAL, "channel": f"cia408-{name}"}, **kw)  # type: ignore[arg-type]


def _abort(fn: object, *args: object) -> int:
    with pytest.raises(canopen.SdoAbortedError) as exc:
        fn(*args)  # type: ignore[operator]
    return int(exc.value.code)


def _operational(r: Cia408Rig) -> None:
    for n in (r.valve, r.encoder):
        n.nmt.state = "OPERATIONAL"
        assert heartbeat_state(n, "OPERATIONAL") == "OPERATIONAL"
        n.tpdo.read(from_od=True)
    r.valve.rpdo.read(from_od=True)


def _command(r: Cia408Rig, control_word: int, setpoint: int) -> None:
    """One RPDO 1: control word + spool set-point."""
    r.valve.rpdo[1][0].raw = control_word
    r.valve.rpdo[1][1].raw = setpoint
    r.valve.rpdo[1].transmit()


def _sync(r: Cia408Rig) -> tuple[int, int, int]:
    """SYNC → (status word, spool actual, position value) from the TPDOs it triggers."""
    for pdo in (r.valve.tpdo[1], r.encoder.tpdo[1]):
        pdo.is_received = False
    r.net.sync.transmit()
    assert wait_until(lambda: r.valve.tpdo[1].is_received and r.encoder.tpdo[1].is_received)
    return r.valve.tpdo[1][0].raw, r.valve.tpdo[1][1].raw, r.encoder.tpdo[1][0].raw


def test_identity_by_sdo_and_aborts_for_bad_accesses() -> None:
    with _rig("sdo") as r:
        assert r.valve.sdo[0x1000].raw == 0x0000_0198  # CiA 408
        assert r.encoder.sdo[0x1000].raw & 0xFFFF == 406
        ident = [r.valve.sdo[0x1018][i].raw for i in (1, 2, 3, 4)]
        assert ident == [0xEE5, 0x408, 0x0001_0000, 1]
        assert r.encoder.sdo[0x1018][2].raw == 0x406
        assert r.valve.sdo[0x1008].raw == "ehpss-hil emulated CiA 408 servo valve"  # segmented upload
        assert r.encoder.sdo[0x6005][1].raw == 100  # nm per step
        assert _abort(r.valve.sdo.upload, 0x2000, 0) == ABORT_NOT_IN_OD
        assert _abort(r.valve.sdo.download, 0x6041, 0, b"\x0f\x00") == ABORT_READ_ONLY
        assert _abort(r.valve.sdo.download, 0x6040, 0, b"\x07") == ABORT_LENGTH
        assert _abort(r.valve.sdo.download, 0x6300, 1, struct.pack("<h", 16385)) == ABORT_RANGE
        assert _abort(r.valve.sdo.download, 0x6042, 0, struct.pack("<b", 2)) == ABORT_RANGE
        r.valve.sdo[0x6300][1].raw = -16384  # in range: stored, read back
        assert r.valve.sdo[0x6300][1].raw == -16384
        r.valve.sdo[0x1017].raw = 50
        assert r.valve.sdo[0x1017].raw == 50


def test_nmt_states_in_the_heartbeat_and_pdos_only_when_operational() -> None:
    with _rig("nmt") as r:
        v = r.valve
        assert heartbeat_state(v, "PRE-OPERATIONAL") == "PRE-OPERATIONAL"
        r.net.sync.transmit()
        _operational(r)
        status, actual, position = _sync(r)
        assert state_of_status(status) == DeviceState.DISABLED
        assert (actual, position) == (0, 0)  # at rest, no current
        # a PDO mapping is not changed while OPERATIONAL
        assert _abort(v.sdo.download, 0x1A00, 1, struct.pack("<I", 0x60410010)) == ABORT_STATE
        v.nmt.state = "STOPPED"
        assert heartbeat_state(v, "STOPPED") == "STOPPED"
        before = r.proc.valve.tpdos
        r.net.sync.transmit()
        r.encoder.tpdo[1].is_received = False
        r.net.sync.transmit()
        assert r.encoder.tpdo[1].wait_for_reception(30) is not None  # the encoder still answers
        assert r.proc.valve.tpdos == before
        states: list[int] = []
        v.nmt.add_heartbeat_callback(states.append)
        v.nmt.send_command(0x81)  # reset node: boot-up, PRE-OPERATIONAL, power-on values
        assert wait_until(lambda: NmtState.BOOT_UP in states)
        assert v.sdo[0x1017].raw == r.cfg.heartbeat_time_ms
        assert r.proc.valve.nmt == NmtState.PRE_OPERATIONAL


def test_setpoint_drives_the_plant_only_when_active() -> None:
    params = load_params()
    with _rig("active") as r:
        _operational(r)
        _command(r, 0x0003, SETPOINT)  # HOLD: the set-point is held back
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.HOLD)
        assert r.proc.valve.current_a() == 0.0
        _command(r, 0x0007, SETPOINT)  # ACTIVE, +20 %
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.ACTIVE)
        assert r.proc.valve.current_a() == pytest.approx(
            SETPOINT / SCALE_100_PERCENT * r.cfg.full_scale_current_a
        )
        k0 = r.emu.k
        assert wait_until(lambda: r.emu.k > k0 + 100)  # the spool settles (poles ≈ −1700 rad/s)
        status, actual, pos1 = _sync(r)
        assert state_of_status(status) == DeviceState.ACTIVE
        p = params.plant
        spool_m = p.valve_gain_m_per_a_s2 / p.valve_stiffness_1_s2 * r.proc.valve.current_a()
        assert actual == pytest.approx(spool_m / p.spool_stroke_m * SCALE_100_PERCENT, abs=2)
        k1 = r.emu.k
        assert wait_until(lambda: r.emu.k > k1 + 50)
        _, _, pos2 = _sync(r)
        assert pos2 > pos1 > 0  # the piston moves out at K_c·x_v
        _command(r, 0x0001, SETPOINT)  # DISABLED: 0 A
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.DISABLED)
        assert r.proc.valve.current_a() == 0.0


def test_master_heartbeat_loss_is_fault_hold_with_emcy_and_a_rising_reset_clears_it() -> None:
    with _rig("hb") as r:
        v = r.valve
        v.sdo[0x1016][1].raw = (r.cfg.master_node << 16) | 50  # consume node 1's heartbeat, 50 ms
        _operational(r)
        _command(r, 0x0007, 1000)
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.ACTIVE)
        r.net.send_message(cobid.HEARTBEAT + r.cfg.master_node, bytes([NmtState.OPERATIONAL]))
        assert wait_until(lambda: EMCY_HEARTBEAT in emcy_codes(v))  # no further heartbeat
        assert wait_until(
            lambda: state_of_status(v.sdo[0x6041].raw) == DeviceState.FAULT_HOLD
        )  # after the reaction
        assert v.sdo[0x1001].raw & 0x11 == 0x11  # generic + communication error
        assert r.proc.valve.current_a() == 0.0
        _command(r, 0x0007, 1000)  # no rising edge of R: the fault stays
        assert wait_until(lambda: r.proc.valve.rpdos >= 2)
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.FAULT_HOLD)  # after its reaction
        _command(r, 0x0008, 0)  # rising edge of R: fault reset → DISABLED, EMCY "no error"
        assert wait_until(lambda: EMCY_NO_ERROR in emcy_codes(v))
        assert state_of_status(v.sdo[0x6041].raw) == DeviceState.DISABLED
        assert v.sdo[0x1001].raw == 0


def test_setpoint_timeout_while_active_is_fault_hold() -> None:
    with _rig("rpdo") as r:
        r.valve.sdo[0x1400][5].raw = 20  # RPDO 1 event timer: 20 ms
        _operational(r)
        _command(r, 0x0007, 2000)
        assert wait_until(lambda: EMCY_RPDO_TIMEOUT in emcy_codes(r.valve))  # no second RPDO
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.FAULT_HOLD)  # after its reaction
        assert r.proc.valve.current_a() == 0.0


def test_a_scenario_device_fault_is_fault_with_its_emcy_code() -> None:
    sc = Scenario(name="dev", duration_s=3600.0, events=(Event(t_s=0.5, device_fault=0x5000),))
    with _rig("dev", scenario=sc) as r:
        _operational(r)  # EMCY is sent in (PRE-)OPERATIONAL
        _command(r, 0x0007, 1000)
        assert wait_until(lambda: 0x5000 in emcy_codes(r.valve), 60.0)
        emcy = next(e for e in r.valve.emcy.log if e.code == 0x5000)
        assert emcy.register == 0x01
        assert wait_until(
            lambda: state_of_status(r.valve.sdo[0x6041].raw) == DeviceState.FAULT
        )  # after the reaction
        assert r.proc.valve.current_a() == 0.0


def test_candump_log_of_a_session_decodes_as_standard_canopen_traffic(tmp_path: Path) -> None:
    """The emulator's own log (every frame it sent and received) read back: each frame belongs to
    a service of the predefined connection set, with that service's length and content."""
    log_path = tmp_path / "cia408.log"
    sc = Scenario(name="log", duration_s=3600.0, events=(Event(t_s=0.3, device_fault=0x2310),))
    with _rig("log", scenario=sc, log_path=log_path) as r:
        assert r.valve.sdo[0x1000].raw == 0x198
        _operational(r)
        for _ in range(5):
            _command(r, 0x0007, 500)
            _sync(r)
        assert wait_until(lambda: 0x2310 in emcy_codes(r.valve), 60.0)
        r.valve.nmt.state = "PRE-OPERATIONAL"
        assert heartbeat_state(r.valve, "PRE-OPERATIONAL") == "PRE-OPERATIONAL"
    frames = list(read_log(log_path))
    seen: dict[str, int] = {}
    valve, encoder = r.cfg.valve_node, r.cfg.encoder_node
    for m in frames:
        service, node = cobid.classify(m.arbitration_id)
        seen[service] = seen.get(service, 0) + 1
        data = bytes(m.data)
        assert service != "UNKNOWN", hex(m.arbitration_id)
        if service == "NMT":
            assert len(data) == 2 and data[1] in (0, valve, encoder)
        elif service == "SYNC":
            assert len(data) == 0
        elif service == "HEARTBEAT":
            assert node in (valve, encoder) and len(data) == 1 and data[0] in set(NmtState)
        elif service in ("SDO_RX", "SDO_TX"):
            assert node == valve and len(data) == 8
        elif service == "TPDO1":
            assert len(data) == 4 and node in (valve, encoder)
        elif service == "RPDO1":
            assert node == valve and len(data) == 4
            assert struct.unpack("<Hh", data) == (0x0007, 500)
        elif service == "EMCY":
            assert node == valve and len(data) == 8
            assert struct.unpack("<HB", data[:3]) == (0x2310, 0x01)
        else:
            pytest.fail(f"unexpected service {service}")
    assert {"NMT", "SYNC", "HEARTBEAT", "SDO_RX", "SDO_TX", "TPDO1", "RPDO1", "EMCY"} <= set(seen)
    assert seen["SYNC"] == 5 and seen["RPDO1"] == 5
    assert seen["TPDO1"] == 2 * 5  # one per node per SYNC while OPERATIONAL
    boot = [m for m in frames if m.arbitration_id == cobid.HEARTBEAT + valve and m.data[0] == 0]
    assert len(boot) == 1  # the boot-up message


def _vcan0_reason() -> str | None:
    if not af_can_available():
        return "this kernel has no SocketCAN (socket(AF_CAN) fails): run via ../shared/tools/vcan-vm/run"
    if not Path("/sys/class/net/vcan0").exists():
        return "vcan0 does not exist (modprobe vcan; ip link add dev vcan0 type vcan; up)"
    return None


@pytest.mark.socketcan
def test_on_socketcan_the_master_reads_identity_and_pdos() -> None:
    reason = _vcan0_reason()
    if reason is not None:
        pytest.skip(reason)
    with Cia408Rig({"interface": "socketcan", "channel": "vcan0"}) as r:
        assert r.valve.sdo[0x1000].raw == 0x198 and r.encoder.sdo[0x1000].raw == 0x80196
        assert r.valve.sdo[0x1018][2].raw == 0x408
        _operational(r)
        status, actual, position = _sync(r)
        assert (state_of_status(status), actual, position) == (DeviceState.DISABLED, 0, 0)
