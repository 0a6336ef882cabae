"""Seeded fuzz frames for every decoder: crafted ones with a known verdict, and random ones.

Crafted frames follow a model of the receiver's E2E profile-2 counter state per CAN ID (the same
rules as :class:`~ehpss_hil.codec.CounterCheck`, written from the specification: delta 0 →
REPEATED, 1 → OK, 2…max → OK_SOME_LOST, larger → WRONG_SEQUENCE without moving the reference), so
each one's verdict is known before any decoder sees it: OK, OK_SOME_LOST, REPEATED,
WRONG_SEQUENCE, CRC_ERROR (CRC byte corrupted), BAD_DLC (DLC 0–8 but not the frame's length),
UNKNOWN_ID (foreign, extended, remote or FD frames) and OUT_OF_RANGE (a correct CRC and counter
over values outside the DBC ranges, NaN/∞ for float signals). Random frames (any ID, DLC 0–8,
random bytes) have no expected verdict: a decoder must only survive and count them.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Any

import can
from cantools.database.can import Message as DbcMessage
from cantools.database.can import Signal

from ..codec import FrameCodec, Verdict
from ..codec.e2e import protect

#: crafted kinds and their weights
KINDS: dict[str, float] = {
    "ok": 0.30,
    "lost": 0.08,
    "implausible": 0.16,
    "repeated": 0.10,
    "wrong_seq": 0.10,
    "crc": 0.10,
    "dlc": 0.10,
    "unknown": 0.06,
}
_EXPECTED = {
    "ok": Verdict.OK,
    "lost": Verdict.OK_SOME_LOST,
    "implausible": Verdict.OUT_OF_RANGE,
    "repeated": Verdict.REPEATED,
    "wrong_seq": Verdict.WRONG_SEQUENCE,
    "crc": Verdict.CRC_ERROR,
    "dlc": Verdict.BAD_DLC,
    "unknown": Verdict.UNKNOWN_ID,
}


@dataclass(frozen=True, slots=True)
class FuzzFrame:
    """One frame and the verdict any correct receiver must give it (None: random frame)."""

    msg: can.Message
    expected: Verdict | None


@dataclass
class _IdState:
    """The modelled receiver counter state of one CAN ID."""

    last: int | None = None
    candidate: int | None = None
    prev: bytes | None = None  # the frame that set ``last`` (resent as a duplicate)


@dataclass
class FrameFuzzer:
    """Generates fuzz frames for the frames of ``codec`` (seeded: same seed, same frames)."""

    codec: FrameCodec
    seed: int = 1
    _rng: random.Random = field(init=False)
    _state: dict[int, _IdState] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.seed)
        self._ids = {self.codec.can_id(n) for n in self.codec.names}

    # ---- public ---------------------------------------------------------------------------
    def crafted(self, n: int) -> list[FuzzFrame]:
        """``n`` frames of random names and kinds, each with its expected verdict."""
        kinds, weights = list(KINDS), list(KINDS.values())
        names = self.codec.names
        return [self._one(self._rng.choice(names), self._rng.choices(kinds, weights)[0]) for _ in range(n)]

    def random(self, n: int) -> list[FuzzFrame]:
        """``n`` frames with random IDs (ours, other 11-bit, 29-bit), DLC 0–8 and bytes."""
        r = self._rng
        ours = sorted(self._ids)
        out = []
        for _ in range(n):
            u = r.random()
            ext = 0.7 <= u < 0.9
            can_id = (
                r.choice(ours) if u < 0.4 or u >= 0.9 else r.getrandbits(29) if ext else r.getrandbits(11)
            )
            dlc = r.randint(0, 8)
            data = r.randbytes(dlc if r.random() < 0.95 else r.randint(0, 8))
            out.append(
                FuzzFrame(
                    can.Message(
                        arbitration_id=can_id,
                        data=data,
                        dlc=dlc,
                        is_extended_id=ext,
                        is_remote_frame=u >= 0.9,
                        check=False,
                    ),
                    None,
                )
            )
        return out

    # ---- crafted frames -------------------------------------------------------------------
    def _one(self, name: str, kind: str) -> FuzzFrame:
        can_id = self.codec.can_id(name)
        st = self._state.setdefault(can_id, _IdState())
        e2e = self.codec.data_ids(name) is not None
        if kind == "unknown":
            return FuzzFrame(self._unknown(can_id), Verdict.UNKNOWN_ID)
        if not e2e and kind in ("lost", "repeated", "wrong_seq", "crc"):
            kind = "ok"
        if st.last is None and kind in ("lost", "repeated", "wrong_seq"):
            kind = "ok"  # the first frame of an ID is accepted whatever its counter
        if kind == "implausible" and not _implausible_signals(self.codec.message(name)):
            kind = "ok"
        if kind == "repeated":
            assert st.prev is not None
            return FuzzFrame(_frame(can_id, st.prev), Verdict.REPEATED)
        counter = self._counter(st, kind)
        data = self._payload(name, counter, implausible=kind == "implausible")
        if kind == "crc":
            data = bytes([data[0] ^ self._rng.randint(1, 255)]) + data[1:]
        elif kind == "dlc":
            return FuzzFrame(self._bad_dlc(can_id, data), Verdict.BAD_DLC)
        else:
            self._advance(st, kind, counter, data)
        return FuzzFrame(_frame(can_id, data), _EXPECTED[kind])

    def _counter(self, st: _IdState, kind: str) -> int:
        """The counter that gives ``kind`` its verdict from the modelled state."""
        r = self._rng
        if st.last is None:
            return r.randint(0, 15)
        max_d = self.codec.max_delta_counter
        if kind == "lost":
            return (st.last + r.randint(2, max_d)) & 0xF
        if kind == "wrong_seq":
            choices = [(st.last + d) & 0xF for d in range(max_d + 1, 16)]
            if st.candidate is not None:  # the candidate's successor would resynchronize
                choices = [c for c in choices if c != (st.candidate + 1) & 0xF]
            return r.choice(choices)
        return (st.last + 1) & 0xF

    @staticmethod
    def _advance(st: _IdState, kind: str, counter: int, data: bytes) -> None:
        if kind == "wrong_seq":
            st.candidate = counter
            return
        st.last, st.candidate, st.prev = counter, None, data

    def _payload(self, name: str, counter: int, implausible: bool) -> bytes:
        """Encoded values (plausible, or with one signal out of range) with counter and CRC."""
        msg = self.codec.message(name)
        values = _plausible_values(msg, self._rng)
        if implausible:
            cands = [s for s in _implausible_signals(msg) if s.name in values]
            if not cands:  # a multiplexed frame whose chosen slot has no such signal
                values = _plausible_values(msg, self._rng, mux_with=_implausible_signals(msg)[0])
                cands = [s for s in _implausible_signals(msg) if s.name in values]
            sig = self._rng.choice(cands)
            values[sig.name] = _out_of_range(sig, self._rng)
        data = bytearray(msg.encode(values, scaling=True, padding=False, strict=False))
        ids = self.codec.data_ids(name)
        return protect(data, counter, ids) if ids is not None else bytes(data)

    def _bad_dlc(self, can_id: int, data: bytes) -> can.Message:
        r = self._rng
        length = len(data)
        dlc = r.choice([d for d in range(9) if d != length])
        if r.random() < 0.8:  # DLC and data agree, both wrong
            return _frame(can_id, (data + r.randbytes(8))[:dlc])
        return can.Message(
            arbitration_id=can_id, data=data, dlc=dlc, is_extended_id=False, check=False
        )  # DLC field disagrees with the bytes

    def _unknown(self, can_id: int) -> can.Message:
        r = self._rng
        data = r.randbytes(8)
        u = r.random()
        if u < 0.4:
            other = can_id
            while other in self._ids:
                other = r.getrandbits(11)
            return can.Message(arbitration_id=other, data=data, is_extended_id=False)
        if u < 0.7:
            return can.Message(arbitration_id=can_id, data=data, is_extended_id=True)
        if u < 0.85:
            return can.Message(arbitration_id=can_id, is_remote_frame=True, dlc=8, is_extended_id=False)
        return can.Message(arbitration_id=can_id, data=data, is_fd=True, is_extended_id=False)


def _frame(can_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, dlc=len(data), is_extended_id=False, check=False)


def _raw_limits(sig: Signal) -> tuple[int, int]:
    if sig.is_signed:
        return -(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1
    return 0, (1 << sig.length) - 1


def _implausible_signals(msg: DbcMessage) -> list[Signal]:
    """Signals that can carry a value outside their DBC range (or a non-finite float)."""
    out = []
    for s in msg.signals:
        if s.name in ("CRC", "Counter") or s.is_multiplexer:
            continue
        if s.is_float:
            out.append(s)
            continue
        if s.minimum is None or s.maximum is None or s.minimum == s.maximum:
            continue
        lo, hi = _raw_limits(s)
        scale, off = float(s.scale), float(s.offset)
        if hi * scale + off > float(s.maximum) + 1.5 * abs(scale) or lo * scale + off < float(
            s.minimum
        ) - 1.5 * abs(scale):
            out.append(s)
    return out


def _out_of_range(sig: Signal, r: random.Random) -> float:
    """A value the signal's bits can hold but its DBC range excludes (NaN/±∞ for floats)."""
    if sig.is_float:
        return r.choice([math.nan, math.inf, -math.inf])
    assert sig.minimum is not None and sig.maximum is not None  # see _implausible_signals
    lo, hi = _raw_limits(sig)
    scale, off = float(sig.scale), float(sig.offset)
    above = math.floor((float(sig.maximum) - off) / scale + 0.5) + 1
    below = math.ceil((float(sig.minimum) - off) / scale - 0.5) - 1
    ranges = [(above, hi)] if above <= hi else []
    if below >= lo:
        ranges.append((lo, below))
    a, b = r.choice(ranges)
    return r.randint(a, b) * scale + off


def _plausible_values(msg: DbcMessage, r: random.Random, mux_with: Signal | None = None) -> dict[str, Any]:
    """Random in-range physical values for every signal of one multiplexer choice."""
    mux = next((s for s in msg.signals if s.is_multiplexer), None)
    chosen: int | None = None
    if mux is not None:
        ids = sorted({i for s in msg.signals for i in (s.multiplexer_ids or [])})
        chosen = (
            mux_with.multiplexer_ids[0]
            if mux_with is not None and mux_with.multiplexer_ids
            else r.choice(ids)
        )
    values: dict[str, Any] = {"CRC": 0, "Counter": 0}
    for s in msg.signals:
        if s.name in values:
            continue
        if s.is_multiplexer:
            values[s.name] = chosen
        elif s.multiplexer_ids is not None and chosen not in s.multiplexer_ids:
            continue
        elif s.is_float:
            values[s.name] = r.uniform(-1e6, 1e6)
        elif s.minimum is not None and s.maximum is not None and s.minimum < s.maximum:
            values[s.name] = r.uniform(float(s.minimum), float(s.maximum))
        else:
            lo, hi = _raw_limits(s)
            values[s.name] = r.randint(lo, hi) * float(s.scale) + float(s.offset)
    return values
