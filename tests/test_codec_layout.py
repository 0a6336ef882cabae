"""The fast codec path equals cantools bit for bit: BitLayout encode/decode against
``Message.encode``/``decode`` for every frame of the DBC (random raw values, the range ends,
rounding ties, every multiplexer id), the table CRC against ``cantools.autosar.end_to_end``, and
FrameCodec's encode/classify against the cantools + crccheck path they replaced."""

from __future__ import annotations

import math
import random
import struct
from typing import Any

import can
import pytest
from cantools.autosar.end_to_end import apply_profile2_crc, check_profile2_crc, compute_profile2_crc
from cantools.database.errors import DecodeError

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.codec.e2e import CounterCheck, E2EState, crc_ok, profile2_crc, protect
from ehpss_hil.codec.layout import BitLayout, LayoutMiss

CODEC = FrameCodec()
NAMES = CODEC.names
N_RANDOM = 300


def _same(a: Any, b: Any) -> bool:
    """Equal value and type; floats compared by their bits (so -0.0 ≠ 0.0 and NaN = NaN)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return struct.pack("<d", a) == struct.pack("<d", b)
    return bool(a == b)


def _same_dict(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)


def _raw_range(sig: Any) -> tuple[int, int]:
    if sig.is_signed:
        return -(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1
    return 0, (1 << sig.length) - 1


def _selections(name: str) -> list[dict[str, int]]:
    """One ``{multiplexer: id}`` per multiplexer id ({} for a plain frame)."""
    msg = CODEC.message(name)
    muxes = [s for s in msg.signals if s.is_multiplexer]
    if not muxes:
        return [{}]
    (mux,) = muxes
    ids = sorted({i for s in msg.signals if s.multiplexer_ids for i in s.multiplexer_ids})
    return [{mux.name: i} for i in ids]


def _signals(name: str, sel: dict[str, int]) -> list[Any]:
    msg = CODEC.message(name)
    return [
        s
        for s in msg.signals
        if s.multiplexer_ids is None or any(i in s.multiplexer_ids for i in sel.values())
    ]


def _physical(sig: Any, rng: random.Random, mode: str) -> Any:
    """A physical value whose raw value is an end of the field, random, or a rounding tie."""
    if sig.conversion.is_float:
        bits = rng.getrandbits(sig.length)
        fmt = ("<I", "<f") if sig.length == 32 else ("<Q", "<d")
        v = struct.unpack(fmt[1], struct.pack(fmt[0], bits))[0]
        return 0.0 if math.isnan(v) or math.isinf(v) else v
    lo, hi = _raw_range(sig)
    raw = {"lo": lo, "hi": hi}.get(mode, rng.randint(lo, hi))
    if sig.is_multiplexer:
        return raw
    phys = raw * sig.scale + sig.offset
    if mode == "tie" and sig.scale != 1:
        phys = (raw + 0.5 if raw < hi else raw - 0.5) * sig.scale + sig.offset
    elif mode == "float" and raw < hi:
        phys = (raw + rng.random()) * sig.scale + sig.offset
    return phys if sig.scale != 1 or mode in ("float", "tie") else int(phys)


@pytest.mark.parametrize("name", NAMES)
def test_layout_encode_equals_cantools(name: str) -> None:
    msg = CODEC.message(name)
    layout = BitLayout.of(msg)
    assert layout is not None, f"{name}: not covered by the fast path"
    rng = random.Random(name)
    for sel in _selections(name):
        sigs = _signals(name, sel)
        for i in range(N_RANDOM):
            mode = ("lo", "hi", "tie", "float", "random")[i % 5]
            values = {s.name: _physical(s, rng, mode) for s in sigs}
            values.update(sel)
            ref = msg.encode(values, scaling=True, padding=False, strict=False)
            assert layout.encode(values) == ref, (name, values)


@pytest.mark.parametrize("name", NAMES)
def test_layout_decode_equals_cantools(name: str) -> None:
    msg = CODEC.message(name)
    layout = BitLayout.of(msg)
    assert layout is not None
    rng = random.Random(name)
    payloads = [bytes([0] * msg.length), bytes([0xFF] * msg.length)]
    payloads += [rng.randbytes(msg.length) for _ in range(20 * N_RANDOM)]
    for data in payloads:
        try:
            ref = msg.decode(data, decode_choices=False, scaling=True, allow_truncated=False)
        except DecodeError:
            with pytest.raises(LayoutMiss):
                layout.decode(data)
            continue
        got = layout.decode(bytearray(data))
        assert _same_dict(got, ref), (name, data.hex(), got, ref)  # type: ignore[arg-type]


def test_layout_misses_what_it_does_not_cover() -> None:
    pos = BitLayout.of(CODEC.message("SENSOR_POS"))
    idx = BitLayout.of(CODEC.message("CTRL_INDEX"))
    assert pos is not None and idx is not None
    with pytest.raises(LayoutMiss):
        pos.encode({"Position": 1.0})  # raw 10 000 000 does not fit 24 bits signed
    with pytest.raises(LayoutMiss):
        pos.encode({"Position": "0.1"})
    with pytest.raises(LayoutMiss):
        idx.encode({"ModelSlot": 3})  # J_3/Theta_3 missing
    with pytest.raises(LayoutMiss):
        pos.decode(b"\x00" * 7)
    # missing top-level signals are 0; `zero` fields are 0 whatever the values say
    assert pos.encode({}) == bytes(8)
    e2e = BitLayout.of(CODEC.message("SENSOR_POS"), frozenset({"CRC", "Counter"}))
    assert e2e is not None and e2e.encode({"CRC": 7, "Counter": 3}) == bytes(8)
    assert pos.encode({"CRC": 7, "Counter": 3}) == b"\x07\x03" + bytes(6)


def test_profile2_crc_equals_cantools_for_every_data_id() -> None:
    rng = random.Random(2)
    for data_id in range(256):
        for n in (2, 3, 8):
            p = rng.randbytes(n)
            assert profile2_crc(p, data_id) == compute_profile2_crc(p, data_id)
    for _ in range(5000):
        p, data_id = rng.randbytes(rng.randint(2, 8)), rng.randrange(256)
        assert profile2_crc(bytearray(p), data_id) == compute_profile2_crc(p, data_id)


def test_protect_and_check_equal_cantools() -> None:
    rng = random.Random(3)
    ids = tuple(range(16, 32))
    for counter in range(40):
        p = bytearray(rng.randbytes(8))
        ref = bytearray(p)
        ref[1] = (ref[1] & 0xF0) | (counter & 0x0F)
        want = apply_profile2_crc(bytes(ref), ids[counter & 0x0F])
        got = protect(p, counter, ids)
        assert got == want and p[1] == ref[1]
        assert crc_ok(got, ids) and check_profile2_crc(got, ids[got[1] & 0x0F])
        bad = bytes([got[0] ^ 1]) + got[1:]
        assert not crc_ok(bad, ids) and not check_profile2_crc(bad, ids[bad[1] & 0x0F])
    assert not crc_ok(b"\x00", ids)


# ---- FrameCodec against the cantools + crccheck implementation it replaced -------------------
def _reference_encode(name: str, values: dict[str, Any], counter: int) -> bytes:
    msg = CODEC.message(name)
    full = {s.name: 0 for s in msg.signals if s.multiplexer_ids is None}
    full.update(values)
    ids = CODEC.data_ids(name)
    if ids is not None:
        full["CRC"] = 0
        full["Counter"] = 0
    data = bytearray(msg.encode(full, scaling=True, padding=False, strict=False))
    if ids is None:
        return bytes(data)
    data[1] = (data[1] & 0xF0) | (counter & 0x0F)
    out = apply_profile2_crc(bytes(data), ids[counter & 0x0F])
    assert out is not None
    return bytes(out)


def _plausible_values(name: str, sel: dict[str, int], rng: random.Random) -> dict[str, Any]:
    out: dict[str, Any] = dict(sel)
    for s in _signals(name, sel):
        if s.name in ("CRC", "Counter") or s.is_multiplexer:
            continue
        if s.minimum is None or s.maximum is None or s.minimum == s.maximum:
            out[s.name] = rng.uniform(-1e6, 1e6) if s.conversion.is_float else 0
        elif s.scale == 1:
            out[s.name] = rng.randint(int(s.minimum), int(s.maximum))
        else:
            out[s.name] = rng.choice([s.minimum, s.maximum, rng.uniform(s.minimum, s.maximum)])
    return out


@pytest.mark.parametrize("name", NAMES)
def test_frame_codec_encode_equals_the_cantools_path(name: str) -> None:
    rng = random.Random(name)
    tx = FrameCodec()
    for sel in _selections(name):
        for k in range(40):
            values = _plausible_values(name, sel, rng)
            counter = tx._tx_counter[name]
            msg = tx.encode(name, values)
            assert bytes(msg.data) == _reference_encode(name, values, counter), (name, values)
            assert msg.dlc == CODEC.message(name).length and not msg.is_extended_id
            if k == 0:
                assert tx.encode(name, values, counter=9).data == _reference_encode(name, values, 9)


def _reference_classify(frame: can.Message, checks: dict[int, CounterCheck]) -> tuple[Verdict, Any]:
    """The classification as cantools + crccheck computed it before the fast path."""
    name = CODEC.name_of(frame.arbitration_id)
    assert name is not None
    msg = CODEC.message(name)
    data = bytes(frame.data)
    ids = CODEC.data_ids(name)
    if ids is not None:
        if not check_profile2_crc(data, ids[data[1] & 0x0F]):
            return Verdict.CRC_ERROR, None
        state = checks.setdefault(frame.arbitration_id, CounterCheck(3)).check(data[1])
        if state is E2EState.REPEATED:
            return Verdict.REPEATED, None
        if state is E2EState.WRONG_SEQUENCE:
            return Verdict.WRONG_SEQUENCE, None
        verdict = Verdict.OK if state is E2EState.OK else Verdict.OK_SOME_LOST
    else:
        verdict = Verdict.OK
    try:
        values = msg.decode(data, decode_choices=False, scaling=True, allow_truncated=False)
        bad = CODEC.check_plausible(name, values)  # type: ignore[arg-type]
    except Exception:
        return Verdict.OUT_OF_RANGE, None
    return (Verdict.OUT_OF_RANGE, None) if bad is not None else (verdict, values)


@pytest.mark.parametrize("name", NAMES)
def test_frame_codec_classify_equals_the_cantools_path(name: str) -> None:
    rng = random.Random(name)
    tx, rx = FrameCodec(), FrameCodec()
    checks: dict[int, CounterCheck] = {}
    can_id, length = CODEC.can_id(name), CODEC.message(name).length
    frames = []
    for sel in _selections(name):
        frames += [tx.encode(name, _plausible_values(name, sel, rng)) for _ in range(10)]
    ids = CODEC.data_ids(name)
    for _ in range(400):  # random payloads: CRC errors, and with a fixed-up CRC, any content
        data = bytearray(rng.randbytes(length))
        if ids is not None and rng.random() < 0.8:
            data[0] = compute_profile2_crc(bytes(data), ids[data[1] & 0x0F]) or 0
        frames.append(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
    for f in frames:
        d = rx.classify(f)
        verdict, values = _reference_classify(f, checks)
        assert d.verdict is verdict and d.name == name
        if values is None:
            assert d.values is None
        else:
            assert d.values is not None and _same_dict(d.values, values)
    assert sum(rx.counts.values()) == len(frames) == sum(rx.counts_by_name[name].values())


_SYNTHETIC_DBC = """VERSION ""
NS_ :
BS_:
BU_: A B
BO_ 100 MOTOROLA: 8 A
 SG_ U12 : 7|12@0+ (1,0) [0|4095] "" B
 SG_ S9 : 11|9@0- (0.5,-3) [0|0] "" B
 SG_ F32 : 31|32@0- (1,0) [0|0] "" B
 SG_ U6 : 63|6@0+ (10,5) [0|0] "" B
 SG_ LE2 : 56|2@1- (0.25,0) [0|0] "" B
BO_ 101 MIXED_MUX: 8 A
 SG_ Sel M : 0|3@1+ (1,0) [0|7] "" B
 SG_ Common : 3|5@1+ (2,0) [0|0] "" B
 SG_ A0 m0 : 8|16@1- (0.01,1) [0|0] "" B
 SG_ A1 m1 : 15|16@0+ (1,0) [0|0] "" B
 SG_ B1 m1 : 31|32@0- (1,0) [0|0] "" B
 SG_ D2 m2 : 8|48@1- (1e-6,0) [0|0] "" B
BO_ 102 SHORT: 3 A
 SG_ X : 0|24@1- (1e-3,0.5) [0|0] "" B
BO_ 103 DOUBLE: 8 A
 SG_ D : 0|64@1- (1,0) [0|0] "" B
SIG_VALTYPE_ 100 F32 : 1;
SIG_VALTYPE_ 101 B1 : 1;
SIG_VALTYPE_ 103 D : 2;
VAL_ 101 Sel 0 "zero" 1 "one" 2 "two" 5 "five" ;
"""


def test_layout_equals_cantools_on_motorola_mux_float_and_short_frames() -> None:
    """Layouts the project DBC does not use (Motorola order, big-endian floats, offsets, choices
    on the multiplexer, a 3-byte frame) against cantools, encode and decode."""
    import cantools

    db = cantools.database.load_string(_SYNTHETIC_DBC, database_format="dbc")
    assert isinstance(db, cantools.database.can.Database)
    rng = random.Random(7)
    for msg in db.messages:
        layout = BitLayout.of(msg)
        assert layout is not None, msg.name
        for _ in range(3000):
            data = rng.randbytes(msg.length)
            try:
                ref = msg.decode(data, decode_choices=False, scaling=True, allow_truncated=False)
            except DecodeError:
                with pytest.raises(LayoutMiss):
                    layout.decode(data)
                continue
            assert isinstance(ref, dict)
            got = layout.decode(data)
            assert _same_dict(got, ref), (msg.name, data.hex())
            values = {k: v for k, v in ref.items() if isinstance(v, (int, float))}
            if any(isinstance(v, float) and not math.isfinite(v) for v in values.values()):
                continue
            want = msg.encode(values, scaling=True, padding=False, strict=False)
            assert layout.encode(values) == want, (msg.name, values)
