"""``protocol: dbc-map`` with the shipped vendor DBC: the bytes on the bus are the vendor's (read
back with cantools by the vendor's own names), E2E is checked, a multiplexed page without the
mapped signals carries no data, and every kind of bad map is one exit-2 line naming its key."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import can
import cantools
import pytest
from cantools.autosar import end_to_end
from cantools.database.can import Database

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.config import load_controller_config
from ehpss_hil.errors import ConfigError
from ehpss_hil.protocol import make_codec
from ehpss_hil.protocol.dbcmap import MappedCodec

ROOT = Path(__file__).resolve().parent.parent
VENDOR_CFG = ROOT / "configs" / "controller-vendor.yaml"
VENDOR_DBC = ROOT / "dbc" / "vendor-example.dbc"


def _vendor_db() -> Database:
    db = cantools.database.load_file(str(VENDOR_DBC))
    assert isinstance(db, Database)
    return db


def _decode(name: str, data: bytes | bytearray) -> dict[str, Any]:
    """The vendor frame read back by cantools with the vendor's own names (raw numbers)."""
    return dict(_vendor_db().decode_message(name, bytes(data), decode_choices=False))  # type: ignore[arg-type]


def _codec(path: Path = VENDOR_CFG) -> FrameCodec:
    cfg = load_controller_config(path)
    return make_codec(cfg.protocol, cfg.dbc, cfg.ids, str(path), cfg.dbc_map)


def test_the_vendor_frames_carry_the_vendor_scaling() -> None:
    emu, ctrl = _codec(), _codec()
    assert isinstance(emu, MappedCodec)
    f = emu.encode("SENSOR_POS", {"Position": 0.0123456, "Spool": -0.00123456})
    assert (f.arbitration_id, f.dlc) == (0x0D2, 8)
    raw = _decode("AMP_FEEDBACK", f.data)
    assert raw["PistonPos"] == pytest.approx(12.3455, abs=1e-9)  # mm, 0.5 µm steps (Motorola)
    assert raw["SpoolPos"] == pytest.approx(-1234.55, abs=1e-9)  # µm, 0.05 µm steps (Intel)
    assert end_to_end.check_profile2_crc(bytes(f.data), 16 + (f.data[1] & 0x0F))
    d = ctrl.classify(f)
    assert d.verdict is Verdict.OK and d.name == "SENSOR_POS" and d.values is not None
    assert d.values["Position"] == pytest.approx(0.0123455, abs=1e-12)
    assert d.values["Spool"] == pytest.approx(-0.00123455, abs=1e-12)
    a = emu.encode("SENSOR_AUX", {"LoadPressure": 2.5e6, "CoilCurrent": -0.25, "ValveEnabled": 1})
    raw = _decode("AMP_STATUS", a.data)
    assert raw["Page"] == 0 and raw["LoadPress"] == pytest.approx(25.0) and raw["CoilCurrent"] == -250.0
    c = ctrl.encode("VALVE_CMD", {"CurrentSetpoint": 0.1234567, "Enable": 1, "CycleCount": 7})
    assert (c.arbitration_id, c.dlc) == (0x0C8, 6)
    raw = _decode("AMP_CMD", c.data)
    assert raw["CurrentDemand"] == pytest.approx(123.4565, abs=1e-9) and raw["DriveEnable"] == 1
    assert emu.classify(c).values == {"CurrentSetpoint": pytest.approx(0.1234565), "Enable": 1.0}


def test_e2e_and_pages() -> None:
    emu, ctrl = _codec(), _codec()
    f = emu.encode("SENSOR_POS", {"Position": 0.001, "Spool": 0.0})
    assert ctrl.classify(f).verdict is Verdict.OK
    assert ctrl.classify(f).verdict is Verdict.REPEATED
    bad = emu.encode("SENSOR_POS", {"Position": 0.001, "Spool": 0.0})
    bad.data[5] ^= 0x01
    assert ctrl.classify(bad).verdict is Verdict.CRC_ERROR
    emu.skip("SENSOR_POS")
    assert ctrl.classify(emu.encode("SENSOR_POS", {"Position": 0.001, "Spool": 0.0})).verdict is (
        Verdict.OK_SOME_LOST
    )
    # page 1 of the multiplexed AMP_STATUS (oil temperature): a good frame without the mapped signals
    msg = _vendor_db().get_message_by_name("AMP_STATUS")
    data = msg.encode({"Crc": 0, "Alive": 0, "Page": 1, "OilTemp": 55, "SupplyPress": 210.0}, strict=False)
    page1 = end_to_end.apply_profile2_crc(data, 32)
    assert page1 is not None
    d = ctrl.classify(can.Message(arbitration_id=0x0D3, is_extended_id=False, data=page1))
    assert d.verdict is Verdict.OK and d.values is None
    # the native IDs of the replaced frames are nobody's now
    native = FrameCodec().encode("SENSOR_POS", {"Position": 0.001, "Spool": 0.0})
    assert ctrl.classify(native).verdict is Verdict.UNKNOWN_ID
    assert ctrl.can_id("CTRL_STATUS") == 0x140


_MAP = """\
protocol: dbc-map
dbc_map:
  dbc: {dbc}
  signals:
    position: {position}
    spool: AMP_FEEDBACK.SpoolPos
    load_pressure: AMP_STATUS.LoadPress
    coil_current: AMP_STATUS.CoilCurrent
    current_setpoint: {setpoint}
    enable: {enable}
  e2e:
    profile: {profile}
{e2e}
"""
_P02 = "\n".join(
    f"    {frame}: {{counter: {msg}.Alive, crc: {msg}.Crc, data_ids: {list(range(base, base + 16))}}}"
    for frame, msg, base in (
        ("sensor_pos", "AMP_FEEDBACK", 16),
        ("sensor_aux", "AMP_STATUS", 32),
        ("valve_cmd", "AMP_CMD", 48),
    )
)
_COUNTER = """\
    sensor_pos: {counter: AMP_FEEDBACK.Alive}
    sensor_aux: {counter: AMP_STATUS.Alive}
    valve_cmd: {counter: AMP_CMD.Alive}"""


def _config(
    tmp: Path,
    *,
    position: str = "AMP_FEEDBACK.PistonPos",
    setpoint: str = "AMP_CMD.CurrentDemand",
    enable: str = "AMP_CMD.DriveEnable",
    profile: str = "p02",
    e2e: str = _P02,
    dbc: str | None = None,
    extra: str = "",
) -> Path:
    p = tmp / "controller.yaml"
    text = _MAP.format(
        dbc=dbc or VENDOR_DBC,
        position=position,
        setpoint=setpoint,
        enable=enable or '""',
        profile=profile,
        e2e=e2e,
    )
    p.write_text(extra + text)
    return p


@pytest.mark.parametrize(("profile", "e2e"), [("counter", _COUNTER), ("none", "")])
def test_counter_only_and_no_e2e(tmp_path: Path, profile: str, e2e: str) -> None:
    cfg = _config(tmp_path, profile=profile, e2e=e2e)
    emu, ctrl = _codec(cfg), _codec(cfg)
    counters = []
    for k in range(20):
        if k == 5:
            emu.skip("SENSOR_POS")  # a frame lost on the way
        d = ctrl.classify(emu.encode("SENSOR_POS", {"Position": 1e-3 * k, "Spool": 0.0}))
        assert d.values is not None and d.values["Position"] == pytest.approx(1e-3 * k)
        counters.append(d.counter)
        assert d.verdict is (Verdict.OK_SOME_LOST if (k == 5 and profile == "counter") else Verdict.OK)
    # counter-only: the sender's counter (a gap at the loss); none: the receiver numbers the frames
    assert counters == [((k + (k >= 5)) if profile == "counter" else k) & 0x0F for k in range(20)]
    f = emu.encode("SENSOR_POS", {"Position": 0.0, "Spool": 0.0})
    f.data[3] ^= 0xFF  # no CRC in these profiles: the corruption goes through as a value
    assert ctrl.classify(f).verdict in (Verdict.OK, Verdict.OUT_OF_RANGE)


def _coarse_dbc(tmp: Path) -> Path:
    text = VENDOR_DBC.read_text().replace(
        'SG_ PistonPos : 23|22@0- (0.0005,0) [-500|500] "mm"',
        'SG_ PistonPos : 23|22@0- (0.005,0) [-500|500] "mm"',
    )
    p = tmp / "coarse.dbc"
    p.write_text(text)
    return p


def _bad_unit_dbc(tmp: Path) -> Path:
    p = tmp / "unit.dbc"
    p.write_text(VENDOR_DBC.read_text().replace('[-500|500] "mm"', '[-500|500] "in"'))
    return p


_SIG = "dbc_map.signals"
_E2E = "dbc_map.e2e.sensor_pos"
#: (what, change to the good map, key named, part of the reason)
BAD_MAPS: list[tuple[str, dict[str, str], str, str]] = [
    ("unknown message", {"position": "AMP_NOPE.PistonPos"}, f"{_SIG}.position", "no message 'AMP_NOPE'"),
    ("unknown signal", {"position": "AMP_FEEDBACK.Piston"}, f"{_SIG}.position", "has no signal 'Piston'"),
    ("not MESSAGE.Signal", {"position": "PistonPos"}, f"{_SIG}.position", "expected MESSAGE.Signal"),
    (
        "too coarse",
        {"dbc": "coarse"},
        f"{_SIG}.position",
        "LSB of 5e-06 (factor 0.005 mm), coarser than the 3e-06",
    ),
    ("unit", {"dbc": "unit"}, f"{_SIG}.position", "has unit 'in'"),
    (
        "split frame",
        {"setpoint": "AMP_STATUS.CoilCurrent"},
        f"{_SIG}.enable",
        "VALVE_CMD's signals must share one message",
    ),
    (
        "one message, two frames",
        {"setpoint": "AMP_STATUS.CoilCurrent", "enable": ""},
        f"{_SIG}.current_setpoint",
        "AMP_STATUS already carries SENSOR_AUX",
    ),
    (
        "id clash",
        {"extra": "ids: {id_base: 0x92}\n"},
        "ids.id_base",
        "AMP_FEEDBACK has ID 0xD2, the ID of our CTRL_STATUS",
    ),
    (
        "no counter",
        {"profile": "p02", "e2e": "    sensor_pos: {crc: AMP_FEEDBACK.Crc}"},
        f"{_E2E}.counter",
        "required with e2e.profile p02",
    ),
    ("p05 layout", {"profile": "p05"}, f"{_E2E}.crc", "p05 puts the CRC at bit 0, 16 bits"),
    (
        "counter in another message",
        {"profile": "counter", "e2e": "    sensor_pos: {counter: AMP_CMD.Alive}"},
        f"{_E2E}.counter",
        "must be a signal of AMP_FEEDBACK",
    ),
]


@pytest.mark.parametrize(("what", "change", "key", "reason"), BAD_MAPS, ids=[b[0] for b in BAD_MAPS])
def test_bad_maps_are_one_line_exit_2_naming_the_key(
    tmp_path: Path, what: str, change: dict[str, str], key: str, reason: str
) -> None:
    dbc = {"coarse": _coarse_dbc, "unit": _bad_unit_dbc}.get(change.pop("dbc", ""), None)
    cfg = _config(tmp_path, dbc=str(dbc(tmp_path)) if dbc else None, **change)
    with pytest.raises(ConfigError) as exc:
        _codec(cfg)
    assert exc.value.key_path == key and reason in exc.value.reason, str(exc.value)
    out = subprocess.run(
        [sys.executable, "-m", "ehpss_hil.cli", "check-config", str(cfg)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert out.returncode == 2 and out.stdout == "", out
    lines = out.stderr.splitlines()
    assert len(lines) == 1 and re.search(rf": {re.escape(key)}: ", lines[0]) and reason in lines[0], lines


def test_a_map_without_its_protocol_and_the_shipped_configs(tmp_path: Path) -> None:
    p = _config(tmp_path)
    p.write_text(p.read_text().replace("protocol: dbc-map", "protocol: native"))
    with pytest.raises(ConfigError, match="dbc_map: only read with protocol: dbc-map"):
        load_controller_config(p)
    files = [str(VENDOR_CFG), str(ROOT / "configs" / "emulator-vendor.yaml")]
    out = subprocess.run(
        [sys.executable, "-m", "ehpss_hil.cli", "check-config", *files],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert out.returncode == 0 and "protocol dbc-map" in out.stdout, out


def test_a_valve_without_spool_actual_is_refused(tmp_path: Path) -> None:
    """No degraded mode: the map needs the spool (docs/hardware.md §1)."""
    p = _config(tmp_path)
    p.write_text(p.read_text().replace("    spool: AMP_FEEDBACK.SpoolPos\n", ""))
    with pytest.raises(ConfigError) as exc:
        _codec(p)
    assert exc.value.key_path == "dbc_map.signals.spool" and "missing required key" in exc.value.reason


def test_current_resolution_leaves_the_sample_clock_its_echo_match() -> None:
    """A setpoint and its echo, each rounded to half of the coarsest LSB accepted, differ by at
    most half of each LSB: within the sample clock's wire_match_a, so the echo still confirms."""
    from ehpss_hil.control.tuning import ControlTuning
    from ehpss_hil.protocol.logical import COIL_CURRENT_RESOLUTION_A, CURRENT_RESOLUTION_A, LOGICAL_SIGNALS

    assert CURRENT_RESOLUTION_A / 2 + COIL_CURRENT_RESOLUTION_A / 2 < ControlTuning().wire_match_a
    assert {s.key: s.resolution for s in LOGICAL_SIGNALS if s.quantity == "current"} == {
        "coil_current": COIL_CURRENT_RESOLUTION_A,
        "current_setpoint": CURRENT_RESOLUTION_A,
    }


_P05_DBC = """VERSION ""
NS_ :
BS_:
BU_: AMP PLC
BO_ 300 P5_POS: 8 AMP
 SG_ Crc : 0|16@1+ (1,0) [0|65535] "" PLC
 SG_ Alive : 16|8@1+ (1,0) [0|255] "" PLC
 SG_ Pos : 24|20@1- (0.001,0) [-500|500] "mm" PLC
 SG_ Spool : 44|20@1- (0.0001,0) [-10|10] "mm" PLC
BO_ 301 P5_AUX: 8 AMP
 SG_ Crc : 0|16@1+ (1,0) [0|65535] "" PLC
 SG_ Alive : 16|8@1+ (1,0) [0|255] "" PLC
 SG_ PL : 24|16@1- (100,0) [-3000000|3000000] "Pa" PLC
 SG_ I : 40|20@1- (2e-06,0) [-1|1] "A" PLC
BO_ 302 P5_CMD: 8 PLC
 SG_ Crc : 0|16@1+ (1,0) [0|65535] "" AMP
 SG_ Alive : 16|8@1+ (1,0) [0|255] "" AMP
 SG_ En : 24|1@1+ (1,0) [0|1] "" AMP
 SG_ I : 32|20@1- (5e-06,0) [-1|1] "A" AMP
"""
_P05_MAP = """\
protocol: dbc-map
dbc_map:
  dbc: p05.dbc
  signals: {position: P5_POS.Pos, spool: P5_POS.Spool, load_pressure: P5_AUX.PL, coil_current: P5_AUX.I,
            current_setpoint: P5_CMD.I, enable: P5_CMD.En}
  e2e:
    profile: p05
    sensor_pos: {counter: P5_POS.Alive, crc: P5_POS.Crc, data_ids: [4660]}
    sensor_aux: {counter: P5_AUX.Alive, crc: P5_AUX.Crc, data_ids: [4661]}
    valve_cmd: {counter: P5_CMD.Alive, crc: P5_CMD.Crc, data_ids: [4662]}
"""


def test_p05_with_an_8_bit_counter(tmp_path: Path) -> None:
    """AUTOSAR profile 5 (CRC16 over bytes 2.., a 16-bit DataID) via cantools, an 8-bit counter:
    its low 4 bits run the sequence check through the wrap at 256."""
    (tmp_path / "p05.dbc").write_text(_P05_DBC)
    cfg = tmp_path / "controller.yaml"
    cfg.write_text(_P05_MAP)
    emu, ctrl = _codec(cfg), _codec(cfg)
    verdicts = []
    for k in range(300):
        if k == 200:
            emu.skip("SENSOR_AUX")  # one lost on the way
        f = emu.encode("SENSOR_AUX", {"LoadPressure": 1e5, "CoilCurrent": 0.012346})
        assert end_to_end.check_profile5_crc(bytes(f.data), 4661)
        d = ctrl.classify(f)
        verdicts.append(d.verdict)
        assert d.counter == (k + (k >= 200)) % 256 & 0x0F
        assert d.values is not None and d.values["CoilCurrent"] == pytest.approx(0.012346)
    assert verdicts.count(Verdict.OK_SOME_LOST) == 1 and verdicts[200] is Verdict.OK_SOME_LOST
    assert verdicts.count(Verdict.OK) == 299
    bad = emu.encode("SENSOR_AUX", {"LoadPressure": 1e5, "CoilCurrent": 0.0})
    bad.data[6] ^= 0x10
    assert ctrl.classify(bad).verdict is Verdict.CRC_ERROR


def test_the_fast_path_packs_the_vendor_messages_as_cantools_does() -> None:
    """Each mapped vendor message's bit layout against cantools' own encode and decode, over
    seeded random values of every signal (Motorola and Intel, offsets, the multiplexed page)."""
    import random

    codec = _codec()
    assert isinstance(codec, MappedCodec)
    rng = random.Random(7)
    for name, msg in codec.mapped.items():
        layout = codec._roles[name].layout
        assert layout is not None, name
        for _ in range(200):
            values: dict[str, Any] = {"Page": 0} if msg.is_multiplexed() else {}
            for sig in msg.signals:
                if (sig.multiplexer_ids is not None and 0 not in sig.multiplexer_ids) or sig.is_multiplexer:
                    continue
                raw = rng.randrange(1 << sig.length) - ((1 << (sig.length - 1)) if sig.is_signed else 0)
                # the CRC is written after packing: the layout packs it as 0
                values[sig.name] = 0 if sig.name == "Crc" else raw * sig.scale + sig.offset
            data = layout.encode(values)
            assert data == msg.encode(values, scaling=True, padding=False, strict=False), (name, values)
            assert layout.decode(data) == msg.decode(data, decode_choices=False), name
