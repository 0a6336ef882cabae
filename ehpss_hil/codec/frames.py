"""Encode and classify the frames of ``dbc/ehpss.dbc``.

The DBC is parsed once; each message's codec is precomputed by cantools, and from it a
:class:`~.layout.BitLayout` (shifts and masks) that encodes and decodes exactly as cantools does
(``strict=False`` encode, ``decode_choices=False`` decode) at a fraction of the cost; whatever the
layout does not cover falls back to cantools itself. Plausibility is our own check (cantools does
not range-check). Every received frame gets exactly one :class:`Verdict`, and the receiver counts
them.

IDs: the application frames of the DBC sit at 0x110–0x16F for ``id_base = 0x100``; a different
``id_base`` shifts them all. Heartbeats are ``0x700 + node id`` (CiA 301).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import cantools
from cantools.database.can import Message as DbcMessage

from .. import DEFAULT_DBC
from ..errors import FrameError, FrameIdError
from .e2e import CounterCheck, E2EState, crc_ok, protect
from .layout import BitLayout, LayoutMiss
from .ratelimit import RateLimit
from .verdict import Decoded, Verdict

DBC_ID_BASE = 0x100
HEARTBEAT_BASE = 0x700
#: largest standard (11-bit) CAN identifier
MAX_STANDARD_ID = 0x7FF
_DBC_NODE_IDS = {"HEARTBEAT_CTRL": 0x01, "HEARTBEAT_EMU": 0x02}

__all__ = ["DBC_ID_BASE", "HEARTBEAT_BASE", "MAX_STANDARD_ID", "Decoded", "FrameCodec", "Verdict"]


@dataclass(frozen=True, slots=True)
class _Spec:
    msg: DbcMessage
    name: str
    length: int  # bytes
    can_id: int
    data_ids: tuple[int, ...] | None  # None: not E2E protected
    bounds: tuple[tuple[str, float | None, float | None], ...]
    bounds_by_name: dict[str, tuple[float | None, float | None]]  # the same, by signal name
    zeros: dict[str, int]  # every non-multiplexed signal at 0 (defaults for encode)
    conversions: dict[str, Any]  # signal name -> cantools conversion (scaling)
    layout: BitLayout | None  # None: cantools only
    e2e_fields: frozenset[str]  # CRC and Counter of a protected frame: encoded as 0, then set


def _data_ids(msg: DbcMessage) -> tuple[int, ...] | None:
    attrs = msg.dbc.attributes if msg.dbc is not None else {}
    attr = attrs.get("E2E_DataIDs")
    if attr is None or not str(attr.value).strip():
        return None
    ids = tuple(int(x) for x in str(attr.value).split(","))
    if len(ids) != 16 or not all(0 <= i <= 0xFF for i in ids):
        raise FrameError(f"{msg.name}: E2E_DataIDs must list 16 values in 0..255")
    return ids


def _bounds(sig: Any) -> tuple[str, float | None, float | None]:
    """A signal's plausible range, widened by half an LSB so exact range ends survive rounding."""
    lo, hi = sig.minimum, sig.maximum
    if lo is None or hi is None or lo == hi:
        return (sig.name, None, None)
    half = abs(float(sig.scale)) / 2
    return (sig.name, float(lo) - half, float(hi) + half)


class FrameCodec:
    """Load-once codec for the project's DBC, with per-frame TX counters and RX state.

    One instance per process and direction set: it holds the transmit counters (one per frame
    name) and the receive counter checks (one per CAN ID) and counts every verdict.
    """

    def __init__(
        self,
        dbc_path: str | Path | None = None,
        id_base: int = DBC_ID_BASE,
        node_ids: dict[str, int] | None = None,
        max_delta_counter: int = 3,
    ) -> None:
        path = Path(dbc_path) if dbc_path is not None else DEFAULT_DBC
        try:
            db = cantools.database.load_file(str(path))
        except (OSError, cantools.database.UnsupportedDatabaseFormatError) as exc:
            raise FrameError(f"cannot load DBC {path}: {exc}") from exc
        if not isinstance(db, cantools.database.can.Database):
            raise FrameError(f"{path} is not a CAN database")
        self.db = db
        if not 0 <= id_base <= 0x7FF - 0x6F:
            raise FrameIdError(f"id_base 0x{id_base:X} puts frames outside the 11-bit ID range")
        nodes = {**_DBC_NODE_IDS, **(node_ids or {})}
        self._by_name: dict[str, _Spec] = {}
        self._by_id: dict[int, _Spec] = {}
        for msg in self.db.messages:
            if msg.name in nodes:
                can_id = HEARTBEAT_BASE + nodes[msg.name]
            else:
                can_id = msg.frame_id - DBC_ID_BASE + id_base
                if not 0 <= can_id <= MAX_STANDARD_ID:
                    raise FrameIdError(
                        f"id_base 0x{id_base:X} puts {msg.name} at 0x{can_id:X}, outside the 11-bit ID range"
                    )
            bounds = tuple(_bounds(s) for s in msg.signals if s.name not in ("CRC", "Counter"))
            zeros = {s.name: 0 for s in msg.signals if s.multiplexer_ids is None}
            conv = {s.name: s.conversion for s in msg.signals}
            data_ids = _data_ids(msg)
            e2e = frozenset(("CRC", "Counter") if data_ids is not None else ())
            spec = _Spec(
                msg,
                msg.name,
                msg.length,
                can_id,
                data_ids,
                bounds,
                {b[0]: b[1:] for b in bounds},
                zeros,
                conv,
                BitLayout.of(msg, e2e),
                e2e,
            )
            if can_id in self._by_id:
                cls = FrameIdError if id_base != DBC_ID_BASE else FrameError
                raise cls(
                    f"id_base 0x{id_base:X} gives {msg.name} and "
                    f"{self._by_id[can_id].msg.name} the same ID 0x{can_id:X}"
                )
            self._by_name[msg.name] = spec
            self._by_id[can_id] = spec
        self.max_delta_counter = max_delta_counter
        self._tx_counter: dict[str, int] = {n: 0 for n in self._by_name}
        self._rx_check: dict[int, CounterCheck] = {}
        #: CAN ID → (signal, its rate check) (:meth:`limit_rate`)
        self._rate: dict[int, tuple[str, RateLimit]] = {}
        self.counts: dict[Verdict, int] = {v: 0 for v in Verdict}
        self.counts_by_name: dict[str, dict[Verdict, int]] = {}

    # ---- lookup -------------------------------------------------------------------------
    def can_id(self, name: str) -> int:
        """The CAN ID of frame ``name`` under this codec's ID base."""
        return self._by_name[name].can_id

    def name_of(self, can_id: int) -> str | None:
        """The frame name for ``can_id``, or None."""
        spec = self._by_id.get(can_id)
        return spec.msg.name if spec else None

    def message(self, name: str) -> DbcMessage:
        """The cantools message object of frame ``name``."""
        return self._by_name[name].msg

    @property
    def names(self) -> list[str]:
        """All frame names of the DBC."""
        return list(self._by_name)

    def shape(self, name: str) -> can.Message:
        """An all-zero frame of ``name``: its ID, ID format and length (a bus's send template)."""
        spec = self._by_name[name]
        return can.Message(
            arbitration_id=spec.can_id, is_extended_id=False, dlc=spec.length, data=bytes(spec.length)
        )

    def signal_bounds(self, name: str) -> dict[str, tuple[float | None, float | None]]:
        """Each signal's DBC range (physical units; None: not given) of frame ``name``."""
        return {s.name: (s.minimum, s.maximum) for s in self._by_name[name].msg.signals}

    def data_ids(self, name: str) -> tuple[int, ...] | None:
        """The 16 E2E DataIDs of frame ``name`` (None when it is not protected)."""
        return self._by_name[name].data_ids

    def limit_rate(self, name: str, signal: str, step_m: float) -> RateLimit:
        """Received ``name`` frames whose ``signal`` moves more than ``step_m`` per sample from
        the previous reading are OUT_OF_RANGE (:class:`~.ratelimit.RateLimit`; an E2E-protected
        frame only, the samples elapsed taken from its counter); returns the check."""
        spec = self._by_name[name]
        if spec.data_ids is None or signal not in spec.bounds_by_name:
            raise FrameError(f"{name}.{signal}: a rate limit needs an E2E-protected signal")
        limit = RateLimit(step_m)
        self._rate[spec.can_id] = (signal, limit)
        return limit

    # ---- transmit ----------------------------------------------------------------------
    def check_plausible(self, name: str, values: dict[str, Any]) -> str | None:
        """Return a reason string if any value is non-finite or outside its DBC range."""
        for sig, lo, hi in self._by_name[name].bounds:
            v = values.get(sig)
            if v is None:
                continue
            if isinstance(v, float) and not math.isfinite(v):
                return f"{sig} is not finite ({v})"
            if lo is not None and hi is not None and not lo <= v <= hi:
                return f"{sig}={v} outside [{lo}, {hi}]"
        return None

    def _implausible(self, spec: _Spec, values: dict[str, Any]) -> str | None:
        """:meth:`check_plausible`, walking only the values given (a multiplexed frame carries a
        few of its many signals); when that finds anything, the ordered walk gives the answer."""
        by_name = spec.bounds_by_name
        try:
            for sig, v in values.items():
                lim = by_name.get(sig)
                if lim is None or v is None:
                    continue
                if isinstance(v, float) and not math.isfinite(v):
                    break
                lo, hi = lim
                if lo is not None and hi is not None and not lo <= v <= hi:
                    break
            else:
                return None
        except TypeError:
            pass
        return self.check_plausible(spec.name, values)

    def encode(
        self, name: str, values: dict[str, Any], timestamp_s: float = 0.0, counter: int | None = None
    ) -> can.Message:
        """Encode ``values`` (physical units) into a protected frame; advances the TX counter.

        Raises :class:`FrameError` for an unknown name or a non-finite/out-of-range value.
        Missing signals are sent as 0.
        """
        spec = self._by_name.get(name)
        if spec is None:
            raise FrameError(f"unknown frame {name!r}")
        bad = self._implausible(spec, values)
        if bad is not None:
            raise FrameError(f"{name}: {bad}")
        data = _payload(spec, values)
        if spec.data_ids is not None:
            if counter is None:
                counter = self._tx_counter[name]
                self._tx_counter[name] = (counter + 1) & 0x0F
            data = protect(bytearray(data), counter, spec.data_ids)
        return can.Message(
            arbitration_id=spec.can_id,
            data=data,
            is_extended_id=False,
            dlc=spec.length,
            timestamp=timestamp_s,
        )

    def skip(self, name: str) -> None:
        """Advance ``name``'s TX counter without a frame: one that was sent and lost on the
        way (the emulator's seeded transport loss), so the receiver sees the gap
        (OK_SOME_LOST), as on a real bus."""
        if name not in self._tx_counter:
            raise FrameError(f"unknown frame {name!r}")
        self._tx_counter[name] = (self._tx_counter[name] + 1) & 0x0F

    def quantize(self, name: str, values: dict[str, float]) -> dict[str, float]:
        """The values a receiver decodes after :meth:`encode` — the same cantools conversions
        (``round((v − offset)/scale)·scale + offset``), without building bytes or CRCs.

        Bit-identical to ``classify(encode(name, values)).values`` for plausible values (a test
        checks this); the lockstep simulator uses it to run far faster than real time.
        """
        conv = self._by_name[name].conversions
        out: dict[str, float] = {}
        for sig, v in values.items():
            c = conv[sig]
            out[sig] = c.raw_to_scaled(c.numeric_scaled_to_raw(v), False)
        return out

    # ---- receive -----------------------------------------------------------------------
    def classify(self, frame: can.Message) -> Decoded:
        """Check and decode one received frame; counts its verdict. A payload the codec cannot
        decode (cantools' DecodeError, a value error of the conversion) is OUT_OF_RANGE; any other
        exception is a bug and propagates."""
        name: str | None = None
        try:
            decoded = self._classify(frame)
        except (cantools.database.DecodeError, ValueError, struct.error):
            spec = self._by_id.get(frame.arbitration_id)
            name = spec.msg.name if spec else None
            decoded = Decoded(Verdict.OUT_OF_RANGE, name, None, frame.timestamp)
        self.counts[decoded.verdict] += 1
        if decoded.name is not None:
            per = self.counts_by_name.get(decoded.name)
            if per is None:
                per = self.counts_by_name[decoded.name] = {v: 0 for v in Verdict}
            per[decoded.verdict] += 1
        return decoded

    def _classify(self, frame: can.Message) -> Decoded:
        ts = frame.timestamp
        spec = self._by_id.get(frame.arbitration_id)
        if (
            spec is None
            or frame.is_extended_id
            or frame.is_remote_frame
            or frame.is_error_frame
            or frame.is_fd
        ):
            return Decoded(Verdict.UNKNOWN_ID, None, None, ts)
        name = spec.name
        data = frame.data
        if frame.dlc != spec.length or len(data) != spec.length:
            return Decoded(Verdict.BAD_DLC, name, None, ts)
        if spec.data_ids is not None:
            if not crc_ok(data, spec.data_ids):
                return Decoded(Verdict.CRC_ERROR, name, None, ts)
            check = self._rx_check.get(spec.can_id)
            if check is None:
                check = self._rx_check[spec.can_id] = CounterCheck(self.max_delta_counter)
            state = check.check(data[1])
            if state is E2EState.REPEATED or state is E2EState.WRONG_SEQUENCE:
                rate = self._rate.get(spec.can_id)
                if rate is not None:
                    rate[1].interrupt()
                return Decoded(
                    Verdict.REPEATED if state is E2EState.REPEATED else Verdict.WRONG_SEQUENCE, name, None, ts
                )
            verdict = Verdict.OK if state is E2EState.OK else Verdict.OK_SOME_LOST
        else:
            verdict = Verdict.OK
        values = _values(spec, data)
        if self._implausible(spec, values) is not None:
            return Decoded(Verdict.OUT_OF_RANGE, name, None, ts)
        rate = self._rate.get(spec.can_id)
        if rate is not None and not rate[1].check(float(values[rate[0]]), data[1] & 0x0F):
            return Decoded(Verdict.OUT_OF_RANGE, name, None, ts)
        return Decoded(verdict, name, values, ts, data[1] & 0x0F if spec.data_ids is not None else None)

    def reset_rx(self) -> None:
        """Forget all receive sequence state (e.g. after a bus restart)."""
        self._rx_check.clear()
        for _, limit in self._rate.values():
            limit.reset()

    @property
    def rejected(self) -> int:
        """Number of received frames whose data was not usable."""
        return sum(n for v, n in self.counts.items() if not v.usable)


def _payload(spec: _Spec, values: dict[str, Any]) -> bytes:
    """The unprotected payload (E2E fields 0); signals missing from ``values`` are 0."""
    if spec.layout is not None:
        try:
            return spec.layout.encode(values)
        except LayoutMiss:
            pass  # cantools decides (and raises what it always raised)
    full = dict(spec.zeros)
    full.update(values)
    for f in spec.e2e_fields:
        full[f] = 0
    return spec.msg.encode(full, scaling=True, padding=False, strict=False)


def _values(spec: _Spec, data: bytes | bytearray) -> dict[str, Any]:
    """Physical values of a payload of the right length (cantools' result, key order too)."""
    if spec.layout is not None:
        try:
            return spec.layout.decode(data)
        except LayoutMiss:
            pass
    return spec.msg.decode(
        bytes(data),
        decode_choices=False,  # type: ignore[return-value]
        scaling=True,
        allow_truncated=False,
    )
