"""A precomputed bit layout per DBC message: cantools' encode/decode as shifts and masks.

cantools packs every frame through bitstruct formats and a per-signal conversion call (≈ 5 µs
for an 8-byte frame). The hot path only needs what a DBC describes: each signal is a bit field
(Intel or Motorola order, signed, unsigned or IEEE float) with a linear conversion, optionally
multiplexed. :class:`BitLayout` is built once from the cantools message (the DBC stays the only
definition) and reproduces ``msg.encode(values, scaling=True, padding=False, strict=False)`` and
``msg.decode(data, decode_choices=False, scaling=True)`` with the same conversion expressions,
so the results are the same objects bit for bit (``tests/test_codec_layout.py`` checks every
frame of the DBC against cantools on random raw values and the range ends).

Anything outside that path — a value that is not an ``int``/``float``, a raw value that does
not fit its field, an unknown multiplexer id — raises :class:`LayoutMiss`, and the caller runs
cantools instead, which then behaves (or raises) exactly as it always did.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from cantools.database.can import Message as DbcMessage
from cantools.database.conversion import (
    BaseConversion,
    IdentityConversion,
    LinearConversion,
    LinearIntegerConversion,
    NamedSignalConversion,
)


class LayoutMiss(Exception):
    """The values or the payload are outside the layout's fast path: use cantools."""


_IDENTITY, _LINEAR_INT, _LINEAR = 0, 1, 2
_FLOAT_FORMATS = {
    32: (struct.Struct("<f"), struct.Struct("<I")),
    64: (struct.Struct("<d"), struct.Struct("<Q")),
}

# name, big-endian, shift, mask, sign bit (0: unsigned or float), float formats or None,
# conversion kind, scale, offset, raw is float (no rounding)
_Field = tuple[str, bool, int, int, int, Any, int, Any, Any, bool]


def _conversion(conv: BaseConversion) -> tuple[int, Any, Any] | None:
    """(kind, scale, offset) of a numeric conversion; named choices use their inner numeric one
    (decode with ``decode_choices=False`` and numeric encode go through it, as in cantools)."""
    if isinstance(conv, NamedSignalConversion):  # the inner conversion, built as cantools does
        conv = BaseConversion.factory(
            scale=conv.scale, offset=conv.offset, choices=None, is_float=conv.is_float
        )
    if type(conv) is IdentityConversion:
        return _IDENTITY, 1, 0
    if type(conv) is LinearIntegerConversion:
        return _LINEAR_INT, conv.scale, conv.offset
    if type(conv) is LinearConversion:
        return _LINEAR, conv.scale, conv.offset
    return None


def _field(sig: Any, n_bits: int) -> _Field | None:
    conv = _conversion(sig.conversion)
    if conv is None or sig.length < 1:
        return None
    floats = None
    if sig.conversion.is_float:
        if sig.length not in _FLOAT_FORMATS:
            return None
        floats = _FLOAT_FORMATS[sig.length]
    if sig.byte_order == "little_endian":
        big, shift = False, sig.start
    else:  # Motorola: start is the MSB's sawtooth number; the field ends `length` bits later
        network_msb = 8 * (sig.start // 8) + (7 - sig.start % 8)
        big, shift = True, n_bits - network_msb - sig.length
    if shift < 0 or shift + sig.length > n_bits:
        return None
    sign = 1 << (sig.length - 1) if sig.is_signed and floats is None else 0
    return (sig.name, big, shift, (1 << sig.length) - 1, sign, floats, *conv, bool(sig.conversion.is_float))


class _Node:
    """One level of cantools' codec tree: its signals and, per multiplexer signal, the node of
    each multiplexer id (the same grouping as ``cantools`` ``Message._create_codec``).

    ``pack(values, le, be)`` and ``unpack(le, be, out)``, compiled once
    (:func:`_compile_pack`, :func:`_compile_unpack`), encode and decode the level's own signals
    (``pack`` as a multiplexed level: every signal required)."""

    __slots__ = ("fields", "muxes", "pack", "unpack")

    def __init__(self, fields: tuple[_Field, ...], muxes: tuple[tuple[str, dict[int, _Node]], ...]):
        self.fields = fields
        self.muxes = muxes
        self.pack: _Pack = _cached("pack", fields, None, lambda: _compile_pack(fields, None))
        self.unpack: Callable[[int, int, dict[str, Any]], None] = _cached(
            "unpack", fields, None, lambda: _compile_unpack(fields)
        )


def _build(msg: DbcMessage, n_bits: int, parent: str | None, mux_id: int | None) -> _Node | None:
    fields: list[_Field] = []
    muxes: list[tuple[str, dict[int, _Node]]] = []
    for sig in msg.signals:
        if sig.multiplexer_signal != parent:
            continue
        if mux_id is not None and (sig.multiplexer_ids is None or mux_id not in sig.multiplexer_ids):
            continue
        f = _field(sig, n_bits)
        if f is None:
            return None
        if sig.is_multiplexer:
            ids: set[int] = set()
            for child in msg.signals:
                if child.multiplexer_signal == sig.name and child.multiplexer_ids is not None:
                    ids.update(child.multiplexer_ids)
            if sig.conversion.choices:
                ids.update(sig.conversion.choices.keys())
            children: dict[int, _Node] = {}
            for i in ids:
                node = _build(msg, n_bits, sig.name, i)
                if node is None:
                    return None
                children[i] = node
            muxes.append((sig.name, children))
        fields.append(f)
    return _Node(tuple(fields), tuple(muxes))


_Pack = Callable[[dict[str, Any], int, int], tuple[int, int]]


def _raw_lines(kind: int, raw_float: bool, i: int) -> list[str]:
    """cantools' ``numeric_scaled_to_raw`` of each conversion class, expression for expression
    (``v`` physical → ``r`` raw; ``S{i}``/``O{i}`` the field's scale and offset objects)."""
    if kind == _LINEAR:
        return [f"r = (v - O{i}) / S{i}"] + ([] if raw_float else ["r = round(r)"])
    if kind == _IDENTITY:
        return ["r = v" if raw_float else "r = round(v)"]
    return [f"r = v - O{i}", f"q, rem = divmod(r, S{i})", f"r = round(q if rem == 0 else r / S{i})"]


#: compiled functions by (kind, repr of the fields, default): every FrameCodec of a process
#: shares them (repr tells 1 from 1.0 and 0.0 from -0.0, which the conversions must keep apart)
_COMPILED: dict[tuple[str, str, int | None], Any] = {}


def _compile(name: str, args: str, body: list[str], env: dict[str, Any]) -> Any:
    """Define function ``name(args)`` with ``body`` in namespace ``env`` and return it."""
    lines = "\n    ".join(body)
    src = f"def {name}({args}):\n    {lines}\n"
    exec(compile(src, f"<layout {name}>", "exec"), env)  # source generated from the DBC only
    return env[name]


def _cached(kind: str, fields: tuple[_Field, ...], default: int | None, make: Callable[[], Any]) -> Any:
    key = (kind, repr(fields), default)
    fn = _COMPILED.get(key)
    if fn is None:
        fn = _COMPILED[key] = make()
    return fn


def _compile_pack(fields: tuple[_Field, ...], default: int | None) -> _Pack:
    """``pack(values, le, be) -> (le, be)``: OR the fields' bits into the little- and big-endian
    payload integers; a field missing from ``values`` takes ``default`` (None: it is required).

    The loop over the fields is written out once per level, with each field's shift, mask and
    conversion as constants (what a per-field interpreter would look up every frame)."""
    env: dict[str, Any] = {"Miss": LayoutMiss, "num": (int, float)}
    body = ["get = values.get"]
    for i, (name, big, shift, mask, sign, floats, kind, scale, offset, raw_float) in enumerate(fields):
        env[f"N{i}"], env[f"S{i}"], env[f"O{i}"] = name, scale, offset
        body += [
            f"v = get(N{i})" if default is None else f"v = get(N{i}, {default!r})",
            f"if not isinstance(v, num): raise Miss(N{i})",
        ]
        body += _raw_lines(kind, raw_float, i)
        if floats is not None:
            env[f"FP{i}"], env[f"FU{i}"] = floats[0].pack, floats[1].unpack
            body.append(f"bits = FU{i}(FP{i}(r))[0]")
        else:
            lo, hi = (-sign, mask - sign) if sign else (0, mask)
            body += [f"if r < {lo} or r > {hi}: raise Miss(N{i})", f"bits = r & {mask}"]
        body.append(f"{'be' if big else 'le'} |= bits << {shift}")
    body.append("return le, be")
    return _compile("pack", "values, le, be", body, env)  # type: ignore[no-any-return]


def _compile_unpack(fields: tuple[_Field, ...]) -> Callable[[int, int, dict[str, Any]], None]:
    """``unpack(le, be, out)``: each field's physical value from the payload integers into
    ``out``, in field order (cantools' key order)."""
    env: dict[str, Any] = {}
    body = ["pass"]
    for i, (name, big, shift, mask, sign, floats, kind, scale, offset, _) in enumerate(fields):
        env[f"N{i}"], env[f"S{i}"], env[f"O{i}"] = name, scale, offset
        body.append(f"raw = ({'be' if big else 'le'} >> {shift}) & {mask}")
        if floats is not None:
            env[f"FP{i}"], env[f"FU{i}"] = floats[1].pack, floats[0].unpack
            body.append(f"raw = FU{i}(FP{i}(raw))[0]")
        elif sign:
            body.append(f"if raw & {sign}: raw -= {sign << 1}")
        body.append(f"out[N{i}] = " + ("raw" if kind == _IDENTITY else f"raw * S{i} + O{i}"))
    return _compile("unpack", "le, be, out", body, env)  # type: ignore[no-any-return]


class BitLayout:
    """Encode/decode of one DBC message without cantools; see the module docstring.

    ``zero``: top-level signals always encoded as 0 whatever the values say (the E2E CRC and
    counter, set afterwards); their bits are computed once here.
    """

    __slots__ = ("_big", "_const", "_length", "_pack_root", "_root", "_zero", "name")

    def __init__(self, root: _Node, length: int, name: str, zero: frozenset[str] = frozenset()) -> None:
        self._root = root
        self._length = length
        self.name = name
        self._big = _has_big(root)
        self._zero = zero
        own = tuple(f for f in root.fields if f[0] not in zero)
        fixed = tuple(f for f in root.fields if f[0] in zero)
        self._pack_root: _Pack = _cached("pack", own, 0, lambda: _compile_pack(own, 0))
        self._const = _cached("pack", fixed, 0, lambda: _compile_pack(fixed, 0))({}, 0, 0)

    @classmethod
    def of(cls, msg: DbcMessage, zero: frozenset[str] = frozenset()) -> BitLayout | None:
        """The layout of ``msg``, or None when it has something the layout does not cover
        (container frames, non-linear conversions, float widths other than 32/64 bits)."""
        if msg.is_container or msg.length < 1:
            return None
        root = _build(msg, 8 * msg.length, None, None)
        return None if root is None else cls(root, msg.length, msg.name, zero)

    # ---- encode ------------------------------------------------------------------------------
    def encode(self, values: dict[str, Any]) -> bytes:
        """``values`` (physical) → payload. Top-level signals missing from ``values`` are 0
        (as when the caller adds them as 0); multiplexed ones must be given."""
        try:
            le, be = self._pack_root(values, *self._const)
            node = self._root
            while node.muxes:
                node = self._select(node, values)
                le, be = node.pack(values, le, be)
        except (TypeError, ValueError, OverflowError, ZeroDivisionError, struct.error) as exc:
            raise LayoutMiss(str(exc)) from None
        n = self._length
        if self._big:
            return (be | int.from_bytes(le.to_bytes(n, "little"), "big")).to_bytes(n, "big")
        return le.to_bytes(n, "little")

    def _select(self, node: _Node, values: dict[str, Any]) -> _Node:
        """The multiplexed node the values select (one multiplexer per level)."""
        if len(node.muxes) != 1:
            raise LayoutMiss("more than one multiplexer on one level")
        name, children = node.muxes[0]
        v = 0 if name in self._zero else values.get(name, 0 if node is self._root else None)
        if not isinstance(v, (int, float)):
            raise LayoutMiss(name)
        child = children.get(int(v))
        if child is None:
            raise LayoutMiss(f"{name}={v}")
        return child

    # ---- decode ------------------------------------------------------------------------------
    def decode(self, data: bytes | bytearray) -> dict[str, Any]:
        """Payload (exactly the message length) → physical values, in cantools' key order."""
        if len(data) != self._length:
            raise LayoutMiss("length")
        le = int.from_bytes(data, "little")
        be = int.from_bytes(data, "big") if self._big else 0
        out: dict[str, Any] = {}
        node: _Node | None = self._root
        while node is not None:
            node.unpack(le, be, out)
            if not node.muxes:
                break
            if len(node.muxes) != 1:
                raise LayoutMiss("more than one multiplexer on one level")
            name, children = node.muxes[0]
            node = children.get(int(out[name]))
            if node is None:
                raise LayoutMiss(f"{name}={out[name]}")
        return out


def _has_big(node: _Node) -> bool:
    return any(f[1] for f in node.fields) or any(
        _has_big(c) for _, children in node.muxes for c in children.values()
    )
