"""A ``dbc_map`` checked against its DBC: every key resolved, or one ConfigError naming it.

What is checked (each a :class:`~ehpss_hil.errors.ConfigError`, exit 2, with the key path):

* ``dbc_map.dbc``: a regular file of at most :data:`~ehpss_hil.limits.MAX_DBC_BYTES`, a CAN DBC
  that loads; mapped messages are classic CAN (≤ 8 bytes);
* ``dbc_map.signals.<key>``: ``MESSAGE.Signal`` names an existing message and signal; its unit
  is one the quantity allows (:data:`~.logical.UNITS`); its LSB (DBC factor × unit) is no
  coarser than the needed resolution (:mod:`.logical`); its scaling is one the codec can compute
  with (a finite, normal, non-zero factor; a finite offset) and its range (the DBC's
  ``[min|max]``, within what its bits hold) is ordered and holds :data:`~.logical.MIN_FIELD_STEPS`
  steps of that resolution; a current holds 0 A (the fail-safe) and ± the coil current of the
  spool's stroke (the controller's command range); the signals of one logical frame share
  one message (and one multiplexer page), the three logical frames use three messages;
* ``dbc_map.e2e.<frame>.counter|crc|data_ids``: present exactly when the profile needs them, in
  the frame's message, a counter of at least 4 bits, the CRC and counter where the AUTOSAR
  profile puts them (p02: CRC byte 0, counter the low nibble of byte 1; p05: CRC bytes 0–1), 16
  DataIDs of 0..255 for p02, one of 0..65535 for p05;
* ``ids.id_base``: no message of the DBC has the (standard) ID of a frame the process still
  sends or reads natively (status, heartbeats, SETPOINT, bench frames).
"""

from __future__ import annotations

import math
import os
import stat
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import cantools
from cantools.database.can import Database
from cantools.database.can import Message as DbcMessage

from ..config import DbcMap, E2EFrameMap
from ..errors import ConfigError
from ..limits import MAX_DBC_BYTES
from .logical import LOGICAL_FRAMES, LOGICAL_SIGNALS, MIN_FIELD_STEPS, UNITS, LogicalSignal

#: counter values the receiver's sequence check tells apart (:class:`~ehpss_hil.codec.CounterCheck`)
MIN_COUNTER_BITS = 4
#: the E2E profiles that carry a CRC, and its field: (start bit, length), Intel byte order
CRC_FIELDS = {"p02": (0, 8), "p05": (0, 16)}
#: p02's counter field (start bit, length), Intel: the low nibble of byte 1
P02_COUNTER = (8, 4)
#: DataIDs a profile takes per frame, and their largest value
DATA_IDS = {"p02": (16, 0xFF), "p05": (1, 0xFFFF)}
#: the widths of a DBC float field (SIG_VALTYPE_ 1: IEEE 754 single, 2: double)
FLOAT_BITS = (32, 64)


@dataclass(frozen=True)
class MappedSignal:
    """A logical signal in a vendor message: native name, vendor name, SI per vendor unit."""

    native: str
    vendor: str
    si_per_unit: float


@dataclass(frozen=True)
class MappedFrame:
    """One logical frame carried by one vendor message."""

    role: str  #: the native frame name (SENSOR_POS, SENSOR_AUX, VALVE_CMD)
    msg: DbcMessage
    signals: tuple[MappedSignal, ...]
    mux: tuple[tuple[str, int], ...]  #: multiplexer signal → page carrying the mapped signals
    profile: str  #: none, counter, p02, p05
    counter: str | None
    counter_bits: int
    crc: str | None
    data_ids: tuple[int, ...]


def check_dbc_file(path: str, src: str, key: str) -> None:
    """``path`` is a regular file of at most :data:`MAX_DBC_BYTES`, or a ConfigError naming
    ``key`` (before cantools reads it: a 20 MB DBC costs cantools gigabytes)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise ConfigError(src, key, f"cannot read {path}: {exc.strerror or exc}") from exc
    if not stat.S_ISREG(st.st_mode):
        raise ConfigError(src, key, f"{path} is not a regular file")
    if st.st_size > MAX_DBC_BYTES:
        raise ConfigError(
            src, key, f"{path} is {st.st_size} bytes; a DBC may have at most {MAX_DBC_BYTES} (limits.py)"
        )


def load_vendor_dbc(path: str, src: str) -> Database:
    """The vendor DBC, or a ConfigError naming ``dbc_map.dbc``."""
    check_dbc_file(path, src, "dbc_map.dbc")
    try:
        db = cantools.database.load_file(path)
    except (OSError, ValueError, cantools.database.UnsupportedDatabaseFormatError) as exc:
        raise ConfigError(src, "dbc_map.dbc", f"cannot load {path}: {exc}") from exc
    if not isinstance(db, Database):
        raise ConfigError(src, "dbc_map.dbc", f"{path} is not a CAN database")
    return db


def _signal(db: Database, ref: str, src: str, key: str) -> tuple[DbcMessage, Any]:
    """``MESSAGE.Signal`` → (message, signal), or a ConfigError naming ``key``."""
    msg_name, dot, sig_name = ref.partition(".")
    if not dot or not msg_name or not sig_name:
        raise ConfigError(src, key, f"expected MESSAGE.Signal, got {ref!r}")
    try:
        msg = db.get_message_by_name(msg_name)
    except KeyError:
        raise ConfigError(src, key, f"no message {msg_name!r} in the DBC") from None
    try:
        sig = msg.get_signal_by_name(sig_name)
    except KeyError:
        raise ConfigError(src, key, f"message {msg_name} has no signal {sig_name!r}") from None
    if msg.length > 8:
        raise ConfigError(src, key, f"{msg_name} is {msg.length} bytes: CAN FD is not supported")
    if sig.conversion.is_float and sig.length not in FLOAT_BITS:
        raise ConfigError(
            src,
            key,
            f"{sig_name} is a {sig.length}-bit float; a DBC float is IEEE 754 single (32 bits) "
            "or double (64 bits)",
        )
    return msg, sig


def _field_range(sig: Any) -> tuple[float, float]:
    """The values ``sig`` carries (its unit): the DBC's ``[min|max]`` (when given and not equal)
    within what its raw bits hold through factor and offset (± inf for a float field)."""
    lo, hi = -math.inf, math.inf
    if not sig.conversion.is_float:
        n = int(sig.length)
        raw = (-(1 << (n - 1)), (1 << (n - 1)) - 1) if sig.is_signed else (0, (1 << n) - 1)
        ends = sorted(float(sig.offset) + float(sig.scale) * r for r in raw)
        lo, hi = ends[0], ends[1]
    if sig.minimum is not None and sig.maximum is not None and sig.minimum != sig.maximum:
        lo, hi = max(lo, float(sig.minimum)), min(hi, float(sig.maximum))
    return lo, hi


def _check_scaling(
    ls: LogicalSignal, sig: Any, si: float, src: str, key: str, stroke_current_a: float
) -> None:
    """Factor, offset and range of a scaled field (see the module docstring)."""
    scale, offset = float(sig.scale), float(sig.offset)
    if not (math.isfinite(scale) and math.isfinite(offset)) or abs(scale) < sys.float_info.min:
        raise ConfigError(
            src,
            key,
            f"{sig.name} has factor {scale:g}, offset {offset:g}: the factor must be a finite normal "
            "number (not 0, not denormal) and the offset finite",
        )
    if sig.minimum is not None and sig.maximum is not None and sig.minimum > sig.maximum:
        raise ConfigError(src, key, f"{sig.name} has the range [{sig.minimum:g}|{sig.maximum:g}]: min > max")
    lo, hi = (x * si for x in _field_range(sig))
    assert ls.resolution is not None
    need = MIN_FIELD_STEPS * ls.resolution
    if not (lo <= hi and hi - lo >= need * (1 - 1e-9)) or math.isnan(hi - lo):
        raise ConfigError(
            src,
            key,
            f"{sig.name} holds [{lo:g}, {hi:g}] SI with factor {scale:g} and offset {offset:g} in "
            f"{sig.length} bits; {ls.key} needs a span of at least {need:g} ({MIN_FIELD_STEPS} steps "
            f"of {ls.resolution:g})",
        )
    if ls.quantity == "current" and not lo <= -stroke_current_a <= 0.0 <= stroke_current_a <= hi:
        raise ConfigError(
            src,
            key,
            f"{sig.name} holds [{lo:g}, {hi:g}] A; the controller commands 0 A (fail-safe) and "
            f"±{stroke_current_a:g} A (the spool's stroke)",
        )


def _si_per_unit(ls: LogicalSignal, sig: Any, src: str, key: str, stroke_current_a: float = 0.0) -> float:
    """The SI value of one unit of ``sig``; checks the unit, the resolution and the scaling."""
    units = UNITS[ls.quantity]
    unit = (sig.unit or "").strip()
    if unit not in units:
        allowed = ", ".join(repr(u) for u in units)
        raise ConfigError(src, key, f"{sig.name} has unit {unit!r}; a {ls.quantity} needs one of {allowed}")
    si = units[unit]
    if ls.resolution is None:
        if sig.conversion.is_float or sig.scale != 1 or sig.offset != 0:
            raise ConfigError(src, key, f"{sig.name} must be a plain 0/1 field (factor 1, offset 0)")
        return si
    _check_scaling(ls, sig, si, src, key, stroke_current_a)
    lsb = abs(float(sig.scale)) * si
    if not sig.conversion.is_float and lsb > ls.resolution * (1 + 1e-9):
        raise ConfigError(
            src,
            key,
            f"{sig.name} has an LSB of {lsb:g} (factor {sig.scale:g} {unit}), coarser than the "
            f"{ls.resolution:g} SI units the controller needs for {ls.key} (protocol/logical.py)",
        )
    return si


def _page(msg: DbcMessage, sig: Any) -> tuple[tuple[str, int], ...]:
    """The multiplexer settings under which ``sig`` is present (outermost first)."""
    out: list[tuple[str, int]] = []
    while sig.multiplexer_signal is not None:
        ids = sig.multiplexer_ids or [0]
        out.append((sig.multiplexer_signal, int(ids[0])))
        sig = msg.get_signal_by_name(sig.multiplexer_signal)
    return tuple(reversed(out))


def _page_text(page: tuple[tuple[str, int], ...]) -> str:
    return ", ".join(f"{m}={v}" for m, v in page) or "no page (not multiplexed)"


def _frame_signals(
    db: DbcMap, vdb: Database, src: str, role: str, stroke_current_a: float
) -> tuple[DbcMessage, list[MappedSignal], Any]:
    """The message, the mapped signals and the multiplexer page of logical frame ``role``. The
    frame's page is the lowest of its signals' pages; a signal on another one is named."""
    msg: DbcMessage | None = None
    mapped: list[MappedSignal] = []
    pages: list[tuple[str, Any, tuple[tuple[str, int], ...]]] = []
    for ls in LOGICAL_SIGNALS:
        if ls.frame != role:
            continue
        ref = getattr(db.signals, ls.key)
        if not ref:
            continue  # an optional key (enable) left empty
        key = f"dbc_map.signals.{ls.key}"
        m, sig = _signal(vdb, ref, src, key)
        if msg is not None and m.name != msg.name:
            raise ConfigError(
                src, key, f"{role}'s signals must share one message ({m.name} here, {msg.name} before)"
            )
        msg = m
        pages.append((ls.key, sig, _page(m, sig)))
        si = _si_per_unit(ls, sig, src, key, stroke_current_a)
        mapped.append(MappedSignal(ls.signal, sig.name, si))
    assert msg is not None  # position, load_pressure and current_setpoint are required keys
    page = min(p for _, _, p in pages)
    for key, sig, p in pages:
        if p != page:
            other_key, other, _ = next(x for x in pages if x[2] == page)
            raise ConfigError(
                src,
                f"dbc_map.signals.{key}",
                f"{sig.name} is on multiplexer page {_page_text(p)}, {other.name} ({other_key}) on "
                f"{_page_text(page)}: {role}'s signals must share one page",
            )
    return msg, mapped, page


def _e2e_field(vdb: Database, msg: DbcMessage, ref: str, src: str, key: str) -> Any:
    m, sig = _signal(vdb, ref, src, key)
    if m.name != msg.name:
        raise ConfigError(src, key, f"must be a signal of {msg.name}, the frame's message (got {m.name})")
    if sig.conversion.is_float or sig.scale != 1 or sig.offset != 0 or sig.is_signed:
        raise ConfigError(src, key, f"{sig.name} must be an unsigned raw field (factor 1, offset 0)")
    return sig


def _e2e(
    profile: str, fm: E2EFrameMap, vdb: Database, msg: DbcMessage, src: str, key: str
) -> tuple[Any, Any]:
    """(counter signal or None, CRC signal or None) of one frame, checked for ``profile``."""
    if profile == "none":
        for name in ("counter", "crc", "data_ids"):
            if getattr(fm, name):
                raise ConfigError(src, f"{key}.{name}", "only with e2e.profile counter, p02 or p05")
        return None, None
    if not fm.counter:
        raise ConfigError(src, f"{key}.counter", f"required with e2e.profile {profile}")
    counter = _e2e_field(vdb, msg, fm.counter, src, f"{key}.counter")
    if counter.length < MIN_COUNTER_BITS:
        raise ConfigError(
            src, f"{key}.counter", f"{counter.name} has {counter.length} bits; at least {MIN_COUNTER_BITS}"
        )
    if profile == "counter":
        for name in ("crc", "data_ids"):
            if getattr(fm, name):
                raise ConfigError(src, f"{key}.{name}", "only with e2e.profile p02 or p05")
        return counter, None
    if not fm.crc:
        raise ConfigError(src, f"{key}.crc", f"required with e2e.profile {profile}")
    crc = _e2e_field(vdb, msg, fm.crc, src, f"{key}.crc")
    start, length = CRC_FIELDS[profile]
    if (crc.start, crc.length, crc.byte_order) != (start, length, "little_endian"):
        raise ConfigError(
            src,
            f"{key}.crc",
            f"{profile} puts the CRC at bit {start}, {length} bits, Intel; {crc.name} is not there",
        )
    if profile == "p02" and (counter.start, counter.length, counter.byte_order) != (
        *P02_COUNTER,
        "little_endian",
    ):
        raise ConfigError(src, f"{key}.counter", "p02 puts the counter in the low nibble of byte 1 (8|4@1+)")
    n, hi = DATA_IDS[profile]
    if len(fm.data_ids) != n or any(i > hi for i in fm.data_ids):
        raise ConfigError(src, f"{key}.data_ids", f"{profile} needs {n} DataID(s) in 0..{hi}")
    return counter, crc


def resolve_map(
    m: DbcMap, src: str, stroke_current_a: float = 0.0
) -> tuple[Database, tuple[MappedFrame, ...]]:
    """The vendor DBC and the three mapped logical frames (ConfigError naming the bad key);
    ``stroke_current_a``: the coil current (A) that moves the spool to its stroke, which the
    current fields must hold either way (0: only 0 A is required)."""
    vdb = load_vendor_dbc(m.dbc, src)
    frames: list[MappedFrame] = []
    used: dict[str, str] = {}
    for role, e2e_key in zip(LOGICAL_FRAMES, ("sensor_pos", "sensor_aux", "valve_cmd"), strict=True):
        msg, signals, page = _frame_signals(m, vdb, src, role, stroke_current_a)
        if msg.name in used:
            first = next(ls.key for ls in LOGICAL_SIGNALS if ls.frame == role)
            raise ConfigError(
                src,
                f"dbc_map.signals.{first}",
                f"{msg.name} already carries {used[msg.name]}: one message per frame",
            )
        used[msg.name] = role
        key = f"dbc_map.e2e.{e2e_key}"
        counter, crc = _e2e(m.e2e.profile, getattr(m.e2e, e2e_key), vdb, msg, src, key)
        frames.append(
            MappedFrame(
                role,
                msg,
                tuple(signals),
                tuple(page),
                m.e2e.profile,
                counter.name if counter is not None else None,
                counter.length if counter is not None else 0,
                crc.name if crc is not None else None,
                tuple(getattr(m.e2e, e2e_key).data_ids),
            )
        )
    return vdb, tuple(frames)


def check_id_clash(vdb: Database, native_ids: Iterable[tuple[str, int]], id_base: int, src: str) -> None:
    """No message of the vendor DBC has the standard ID of a frame still sent or read natively."""
    taken = dict((can_id, name) for name, can_id in native_ids)
    for msg in vdb.messages:
        if msg.is_extended_frame:
            continue
        other = taken.get(msg.frame_id)
        if other is not None:
            raise ConfigError(
                src,
                "ids.id_base",
                f"the vendor DBC's {msg.name} has ID 0x{msg.frame_id:X}, the ID of our {other} at id_base "
                f"0x{id_base:X}; move id_base",
            )
