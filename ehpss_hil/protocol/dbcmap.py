"""``protocol: dbc-map``: the three valve frames through a vendor DBC, everything else native.

:class:`MappedCodec` is a :class:`~ehpss_hil.codec.FrameCodec` (the interface the loops, the
emulator and the lockstep transport use) whose logical frames SENSOR_POS, SENSOR_AUX and
VALVE_CMD are the vendor messages of the map (:mod:`.mapcheck`): encode takes and classify gives
the native signal names in SI units, so the controller's cycle, the driver and the emulator do
not know which profile runs. Scaling is the vendor DBC's (cantools: any width, Intel or
Motorola, multiplexed messages: the mapped page's multiplexer is set on encode, a frame of
another page is classified OK without values); the DBC unit picks the SI factor. E2E per the
map: none (the receiver numbers the frames it gets: a lost one is not seen), a counter (the
profile-2 style sequence check on its low 4 bits), AUTOSAR p02/p05 CRCs (cantools'
``autosar.end_to_end`` functions, below). Status, heartbeat, SETPOINT and bench frames stay native at
``id_base`` (no vendor ID may clash with them: :func:`.mapcheck.check_id_clash`).

The hot path is the native codec's: each vendor message's bit layout
(:class:`~ehpss_hil.codec.layout.BitLayout`) packs and unpacks exactly as cantools does
(cantools itself for anything outside it), and the P02 CRC is the table CRC of
:mod:`ehpss_hil.codec.e2e`, the function ``cantools.autosar.end_to_end.compute_profile2_crc``
computes (tests check the vendor frames with cantools' own decode and ``check_profile2_crc``);
P05 runs through cantools.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import can
import cantools
from cantools.autosar import end_to_end
from cantools.database.can import Message as DbcMessage

from ..codec import CounterCheck, Decoded, E2EState, FrameCodec, Verdict
from ..codec.e2e import profile2_crc
from ..codec.layout import BitLayout, LayoutMiss
from ..codec.ratelimit import RateLimit
from ..errors import FrameError
from .mapcheck import MappedFrame


def _bounds(sig: Any, si: float) -> tuple[float, float] | None:
    """A vendor signal's range in SI, widened by half an LSB (None: the DBC gives none)."""
    lo, hi = sig.minimum, sig.maximum
    if lo is None or hi is None or lo == hi:
        return None
    half = abs(float(sig.scale)) / 2
    return ((float(lo) - half) * si, (float(hi) + half) * si)


class _Role:
    """Encode/classify state of one mapped logical frame."""

    def __init__(self, f: MappedFrame, max_delta_counter: int) -> None:
        self.f = f
        self.msg = f.msg
        self.defaults: dict[str, Any] = {}
        page = dict(f.mux)
        for sig in f.msg.signals:
            present = sig.multiplexer_signal is None or page.get(sig.multiplexer_signal) in (
                sig.multiplexer_ids or ()
            )
            if present:
                lo = sig.minimum if sig.minimum is not None else 0
                hi = sig.maximum if sig.maximum is not None else 0
                self.defaults[sig.name] = min(max(0, lo), hi) if lo <= hi else 0
        self.defaults.update(page)
        #: native name → (vendor name, SI per unit, SI bounds or None)
        self.to_vendor = {
            s.native: (s.vendor, s.si_per_unit, _bounds(f.msg.get_signal_by_name(s.vendor), s.si_per_unit))
            for s in f.signals
        }
        self.counter_mod = 1 << f.counter_bits if f.counter else 0
        self.tx_counter = 0
        self.rx_frames = 0  # frames received (the counter when the map has none)
        self.check = CounterCheck(max_delta_counter) if f.counter else None
        self.rate: tuple[str, RateLimit] | None = None
        #: the precomputed bit layout (cantools' encode/decode as shifts and masks; None: cantools)
        self.layout = BitLayout.of(f.msg, frozenset((f.crc,)) if f.crc else frozenset())
        self.shape = can.Message(
            arbitration_id=f.msg.frame_id,
            is_extended_id=f.msg.is_extended_frame,
            dlc=f.msg.length,
            data=bytes(f.msg.length),
        )

    def encode(self, values: dict[str, Any], timestamp_s: float) -> can.Message:
        f = self.f
        data = dict(self.defaults)
        for native, v in values.items():
            m = self.to_vendor.get(native)
            if m is None:
                continue  # a native signal the vendor frame does not carry
            vendor, si, lim = m
            x = float(v)
            if not math.isfinite(x) or (lim is not None and not lim[0] <= x <= lim[1]):
                raise FrameError(f"{f.role} ({f.msg.name}): {native}={x} outside the vendor range")
            data[vendor] = x / si
        counter = 0
        if f.counter is not None:
            counter = self.tx_counter
            self.tx_counter = (counter + 1) % self.counter_mod
            data[f.counter] = counter
        if f.crc is not None:
            data[f.crc] = 0
        payload = bytearray(self._pack(data))
        if f.profile == "p02":
            payload[0] = profile2_crc(payload, f.data_ids[counter & 0x0F])
        elif f.profile == "p05":
            payload = end_to_end.apply_profile5_crc(bytes(payload), f.data_ids[0]) or payload
        return can.Message(
            arbitration_id=f.msg.frame_id,
            is_extended_id=f.msg.is_extended_frame,
            data=bytes(payload),
            dlc=f.msg.length,
            timestamp=timestamp_s,
        )

    def _pack(self, data: dict[str, Any]) -> bytes:
        if self.layout is not None:
            try:
                return self.layout.encode(data)
            except LayoutMiss:
                pass  # cantools decides (and raises what it always raised)
        return self.f.msg.encode(data, scaling=True, padding=False, strict=False)

    def _unpack(self, data: bytes) -> dict[str, Any]:
        if self.layout is not None:
            try:
                return self.layout.decode(data)
            except LayoutMiss:
                pass
        return self.f.msg.decode(  # type: ignore[return-value]
            data, decode_choices=False, scaling=True, allow_truncated=False
        )

    def crc_ok(self, data: bytes, counter: int) -> bool:
        f = self.f
        if f.profile == "p02":
            return data[0] == profile2_crc(data, f.data_ids[counter & 0x0F])
        if f.profile == "p05":
            return bool(end_to_end.check_profile5_crc(data, f.data_ids[0]))
        return True

    def classify(self, frame: can.Message) -> Decoded:
        f, ts = self.f, frame.timestamp
        data = bytes(frame.data)
        if frame.dlc != f.msg.length or len(data) != f.msg.length:
            return Decoded(Verdict.BAD_DLC, f.role, None, ts)
        raw = self._unpack(data)
        verdict = Verdict.OK
        if self.check is not None and f.counter is not None:
            counter = int(raw[f.counter])
            if not self.crc_ok(data, counter):
                return Decoded(Verdict.CRC_ERROR, f.role, None, ts)
            state = self.check.check(counter & 0x0F)
            if state is E2EState.REPEATED or state is E2EState.WRONG_SEQUENCE:
                if self.rate is not None:
                    self.rate[1].interrupt()
                v = Verdict.REPEATED if state is E2EState.REPEATED else Verdict.WRONG_SEQUENCE
                return Decoded(v, f.role, None, ts)
            verdict = Verdict.OK if state is E2EState.OK else Verdict.OK_SOME_LOST
        else:
            counter = self.rx_frames
            self.rx_frames += 1
        values: dict[str, Any] = {}
        for native, (vendor, si, lim) in self.to_vendor.items():
            if vendor not in raw:
                return Decoded(verdict, f.role, None, ts, counter & 0x0F)  # another mux page
            x = float(raw[vendor]) * si
            if not math.isfinite(x) or (lim is not None and not lim[0] <= x <= lim[1]):
                return Decoded(Verdict.OUT_OF_RANGE, f.role, None, ts)
            values[native] = x
        if self.rate is not None and not self.rate[1].check(float(values[self.rate[0]]), counter & 0x0F):
            return Decoded(Verdict.OUT_OF_RANGE, f.role, None, ts)
        return Decoded(verdict, f.role, values, ts, counter & 0x0F)


class MappedCodec(FrameCodec):
    """The native codec with SENSOR_POS, SENSOR_AUX and VALVE_CMD replaced by vendor messages."""

    def __init__(
        self,
        frames: tuple[MappedFrame, ...],
        dbc_path: str | Path | None = None,
        id_base: int = 0x100,
        node_ids: dict[str, int] | None = None,
        max_delta_counter: int = 3,
    ) -> None:
        super().__init__(dbc_path, id_base, node_ids, max_delta_counter)
        self._roles = {f.role: _Role(f, max_delta_counter) for f in frames}
        self._role_by_id = {(r.msg.frame_id, r.msg.is_extended_frame): r for r in self._roles.values()}
        for role in self._roles:  # the native IDs of the replaced frames are no longer read
            self._by_id.pop(super().can_id(role), None)

    @property
    def mapped(self) -> dict[str, DbcMessage]:
        """Logical frame name → the vendor message carrying it."""
        return {name: r.msg for name, r in self._roles.items()}

    def native_ids(self) -> list[tuple[str, int]]:
        """(name, ID) of every frame this codec still handles natively."""
        return [(n, super(MappedCodec, self).can_id(n)) for n in self.names if n not in self._roles]

    def can_id(self, name: str) -> int:
        r = self._roles.get(name)
        return r.msg.frame_id if r is not None else super().can_id(name)

    def name_of(self, can_id: int) -> str | None:
        r = self._role_by_id.get((can_id, False)) or self._role_by_id.get((can_id, True))
        return r.f.role if r is not None else super().name_of(can_id)

    def message(self, name: str) -> DbcMessage:
        """The cantools message of frame ``name``: the vendor's (its own signal names) for a
        mapped logical frame."""
        r = self._roles.get(name)
        return r.msg if r is not None else super().message(name)

    def shape(self, name: str) -> can.Message:
        r = self._roles.get(name)
        return r.shape if r is not None else super().shape(name)

    def data_ids(self, name: str) -> tuple[int, ...] | None:
        r = self._roles.get(name)
        if r is None:
            return super().data_ids(name)
        return r.f.data_ids or None

    def signal_bounds(self, name: str) -> dict[str, tuple[float | None, float | None]]:
        r = self._roles.get(name)
        if r is None:
            return super().signal_bounds(name)
        out: dict[str, tuple[float | None, float | None]] = {}
        for native, (vendor, si, _) in r.to_vendor.items():
            sig = r.msg.get_signal_by_name(vendor)
            lo, hi = sig.minimum, sig.maximum
            out[native] = (None if lo is None else lo * si, None if hi is None else hi * si)
        return out

    def limit_rate(self, name: str, signal: str, step_m: float) -> RateLimit:
        r = self._roles.get(name)
        if r is None:
            return super().limit_rate(name, signal, step_m)
        if signal not in r.to_vendor:
            raise FrameError(f"{name}.{signal}: a rate limit needs a mapped signal")
        limit = RateLimit(step_m)
        r.rate = (signal, limit)
        return limit

    def encode(
        self, name: str, values: dict[str, Any], timestamp_s: float = 0.0, counter: int | None = None
    ) -> can.Message:
        r = self._roles.get(name)
        if r is None:
            return super().encode(name, values, timestamp_s, counter)
        return r.encode(values, timestamp_s)

    def skip(self, name: str) -> None:
        r = self._roles.get(name)
        if r is None:
            super().skip(name)
        elif r.counter_mod:
            r.tx_counter = (r.tx_counter + 1) % r.counter_mod

    def quantize(self, name: str, values: dict[str, float]) -> dict[str, float]:
        if name in self._roles:
            raise FrameError(f"{name}: quantize is native only; use encode + classify under dbc-map")
        return super().quantize(name, values)

    def classify(self, frame: can.Message) -> Decoded:
        r = self._role_by_id.get((frame.arbitration_id, bool(frame.is_extended_id)))
        if r is None or frame.is_remote_frame or frame.is_error_frame or frame.is_fd:
            return super().classify(frame)
        try:
            d = r.classify(frame)
        except (cantools.database.DecodeError, ValueError, struct.error):
            d = Decoded(Verdict.OUT_OF_RANGE, r.f.role, None, frame.timestamp)
        self.counts[d.verdict] += 1
        per = self.counts_by_name.get(r.f.role)
        if per is None:
            per = self.counts_by_name[r.f.role] = {v: 0 for v in Verdict}
        per[d.verdict] += 1
        return d

    def reset_rx(self) -> None:
        super().reset_rx()
        for r in self._roles.values():
            if r.check is not None:
                r.check.reset()
            if r.rate is not None:
                r.rate[1].reset()
