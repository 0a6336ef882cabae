"""Frame contract: round trips within one LSB, every rejection reason, the DBC loads in cantools."""

from __future__ import annotations

import subprocess
import sys

import can
import pytest
from cantools.database.can import Signal
from hypothesis import given, settings
from hypothesis import strategies as st

from ehpss_hil import DEFAULT_DBC
from ehpss_hil.codec import FrameCodec, Verdict, counter_steps
from ehpss_hil.codec.e2e import CounterCheck, E2EState, protect
from ehpss_hil.errors import FrameError

CODEC = FrameCodec()


def _physical_signals(name: str) -> list[tuple[str, float, float, float]]:
    """(signal, min, max, lsb) for every signal of ``name`` with a finite DBC range."""
    out = []
    for s in CODEC.message(name).signals:
        if s.name in ("CRC", "Counter") or s.minimum is None or s.minimum == s.maximum:
            continue
        assert s.maximum is not None, f"{name}.{s.name} has a minimum but no maximum"
        out.append((s.name, float(s.minimum), float(s.maximum), float(s.scale)))
    return out


def _mux_free(name: str) -> bool:
    return not CODEC.message(name).is_multiplexed()


FRAMES = [n for n in CODEC.names if _mux_free(n)]


@pytest.mark.parametrize("name", FRAMES)
@pytest.mark.parametrize("end", ["min", "max"])
def test_round_trip_at_range_ends(name: str, end: str) -> None:
    tx, rx = FrameCodec(), FrameCodec()
    sigs = _physical_signals(name)
    values = {s: (lo if end == "min" else hi) for s, lo, hi, _ in sigs}
    dec = rx.classify(tx.encode(name, values))
    assert dec.verdict is Verdict.OK and dec.name == name and dec.values is not None
    for s, _lo, _hi, lsb in sigs:
        assert abs(dec.values[s] - values[s]) <= lsb / 2 + 1e-15, s


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_round_trip_random_values_within_one_lsb(data: st.DataObject) -> None:
    name = data.draw(st.sampled_from(FRAMES))
    tx, rx = FrameCodec(), FrameCodec()
    values = {
        s: data.draw(st.floats(lo, hi)) if lsb != 1 else data.draw(st.integers(int(lo), int(hi)))
        for s, lo, hi, lsb in _physical_signals(name)
    }
    dec = rx.classify(tx.encode(name, values))
    assert dec.verdict is Verdict.OK and dec.values is not None
    for s, _lo, _hi, lsb in _physical_signals(name):
        assert abs(dec.values[s] - values[s]) <= lsb, s
    # the fast path used by the lockstep simulator is bit-identical to bytes + decode
    q = tx.quantize(name, values)
    assert all(q[s] == dec.values[s] for s in values)


def test_multiplexed_index_frame_round_trip() -> None:
    tx, rx = FrameCodec(), FrameCodec()
    for slot in range(16):
        dec = rx.classify(
            tx.encode("CTRL_INDEX", {"ModelSlot": slot, f"J_{slot}": 0.125 * slot, f"Theta_{slot}": 0.5})
        )
        assert dec.verdict is Verdict.OK and dec.values is not None
        assert dec.values["ModelSlot"] == slot and dec.values[f"J_{slot}"] == 0.125 * slot


def _maximum(s: Signal) -> float:
    assert s.maximum is not None, f"{s.name} has no DBC maximum"
    return s.maximum


def test_resolution_and_range_meet_the_design() -> None:
    sig = {s.name: s for s in CODEC.message("SENSOR_POS").signals}
    assert sig["Position"].scale <= 1e-7 and _maximum(sig["Position"]) >= 0.5
    assert sig["Spool"].scale <= 0.5e-6 and _maximum(sig["Spool"]) >= 0.01
    aux = {s.name: s for s in CODEC.message("SENSOR_AUX").signals}
    assert aux["CoilCurrent"].scale <= 10e-6 and _maximum(aux["CoilCurrent"]) >= 1.0
    # the 24-bit raw range really covers the declared physical range
    for s in (sig["Position"], sig["Spool"], aux["CoilCurrent"]):
        assert 2 ** (s.length - 1) * s.scale >= _maximum(s)


def _sensor(tx: FrameCodec, counter: int | None = None) -> can.Message:
    return tx.encode("SENSOR_POS", {"Position": 1e-3, "Spool": 1e-4}, counter=counter)


def test_each_rejection_reason_is_classified_and_counted() -> None:
    tx, rx = FrameCodec(), FrameCodec()
    assert rx.classify(_sensor(tx, 0)).verdict is Verdict.OK
    assert rx.classify(_sensor(tx, 0)).verdict is Verdict.REPEATED
    assert rx.classify(_sensor(tx, 1)).verdict is Verdict.OK
    assert rx.classify(_sensor(tx, 3)).verdict is Verdict.OK_SOME_LOST
    assert rx.classify(_sensor(tx, 12)).verdict is Verdict.WRONG_SEQUENCE
    good = _sensor(tx, 4)
    bad_crc = bytearray(good.data)
    bad_crc[0] ^= 0x01
    assert (
        rx.classify(
            can.Message(arbitration_id=good.arbitration_id, data=bad_crc, is_extended_id=False)
        ).verdict
        is Verdict.CRC_ERROR
    )
    flipped = bytearray(good.data)
    flipped[5] ^= 0x10  # payload bit flip, CRC unchanged
    assert (
        rx.classify(
            can.Message(arbitration_id=good.arbitration_id, data=flipped, is_extended_id=False)
        ).verdict
        is Verdict.CRC_ERROR
    )
    assert (
        rx.classify(
            can.Message(arbitration_id=good.arbitration_id, data=good.data[:7], is_extended_id=False)
        ).verdict
        is Verdict.BAD_DLC
    )
    assert (
        rx.classify(can.Message(arbitration_id=0x7FF, data=b"\0" * 8, is_extended_id=False)).verdict
        is Verdict.UNKNOWN_ID
    )
    assert (
        rx.classify(
            can.Message(arbitration_id=good.arbitration_id, data=good.data, is_extended_id=True)
        ).verdict
        is Verdict.UNKNOWN_ID
    )
    # valid CRC and counter but a position beyond ±0.5 m: raw 0x7FFFFF·1e-7 = 0.839 m
    raw = bytearray(
        CODEC.message("SENSOR_POS").encode(
            {"CRC": 0, "Counter": 0, "Position": 0.8, "Spool": 0.0}, strict=False
        )
    )
    ids = CODEC.data_ids("SENSOR_POS")
    assert ids is not None
    implausible = protect(raw, 5, ids)
    assert (
        rx.classify(
            can.Message(arbitration_id=good.arbitration_id, data=implausible, is_extended_id=False)
        ).verdict
        is Verdict.OUT_OF_RANGE
    )
    c = rx.counts
    assert (c[Verdict.OK], c[Verdict.REPEATED], c[Verdict.OK_SOME_LOST]) == (2, 1, 1)
    assert (c[Verdict.WRONG_SEQUENCE], c[Verdict.CRC_ERROR], c[Verdict.BAD_DLC]) == (1, 2, 1)
    assert (c[Verdict.UNKNOWN_ID], c[Verdict.OUT_OF_RANGE]) == (2, 1)
    assert rx.rejected == 8


def test_counter_check_never_accepts_a_reordered_frame_twice() -> None:
    cc = CounterCheck(max_delta=3)
    seq = [cc.check(c) for c in (5, 6, 5, 6, 7)]
    assert seq == [E2EState.OK, E2EState.OK, E2EState.WRONG_SEQUENCE, E2EState.REPEATED, E2EState.OK]
    # after a long gap, two frames in sequence resynchronize
    assert cc.check(14) is E2EState.WRONG_SEQUENCE
    assert cc.check(15) is E2EState.OK_SOME_LOST
    assert cc.check(0) is E2EState.OK


def test_crc_is_cantools_profile2_with_per_counter_data_id() -> None:
    from cantools.autosar.end_to_end import compute_profile2_crc

    tx = FrameCodec()
    ids = tx.data_ids("VALVE_CMD")
    assert ids is not None and len(set(ids)) == 16
    for k in range(16):
        m = tx.encode("VALVE_CMD", {"CurrentSetpoint": 1e-4, "Enable": 1})
        assert m.data[1] & 0x0F == k
        assert m.data[0] == compute_profile2_crc(bytes(m.data), ids[k])


def test_encode_rejects_implausible_values_and_unknown_frames() -> None:
    tx = FrameCodec()
    with pytest.raises(FrameError, match="CurrentSetpoint"):
        tx.encode("VALVE_CMD", {"CurrentSetpoint": 2.0})
    with pytest.raises(FrameError, match="not finite"):
        tx.encode("VALVE_CMD", {"CurrentSetpoint": float("nan")})
    with pytest.raises(FrameError, match="unknown frame"):
        tx.encode("NOPE", {})


def test_id_base_shifts_application_frames_not_heartbeats() -> None:
    c = FrameCodec(id_base=0x300, node_ids={"HEARTBEAT_CTRL": 5})
    assert c.can_id("SENSOR_POS") == 0x310 and c.can_id("VALVE_CMD") == 0x320
    assert c.can_id("HEARTBEAT_CTRL") == 0x705 and c.can_id("HEARTBEAT_EMU") == 0x702
    with pytest.raises(FrameError):
        FrameCodec(id_base=0x7F0)


def test_cantools_dump_reads_the_dbc() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "cantools", "dump", str(DEFAULT_DBC)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    for name in CODEC.names:
        assert f"Name:           {name}" in out


def test_counter_steps_counts_samples_across_the_wrap() -> None:
    """Samples between two E2E counters (what the controller's ``Measurement.samples`` is):
    1 for the next frame, the wrap from 15 to 0 included, 16 for a whole wrap; consistent with
    the receiver's sequence check (delta 1 → OK, 2…3 → OK_SOME_LOST)."""
    assert [counter_steps(c, p) for c, p in ((3, 2), (0, 15), (2, 15), (5, 5), (1, 13))] == [1, 1, 3, 16, 4]
    chk = CounterCheck(3)
    chk.check(14)
    assert chk.check(1) is E2EState.OK_SOME_LOST and counter_steps(1, 14) == 3
