"""YAML → frozen dataclasses, with precise errors.

One small, generic builder: a frozen dataclass declares its keys, their types and (through
``field(metadata=...)``) their ranges; :func:`build` walks a parsed YAML mapping, rejects unknown
keys, missing required keys, wrong types and out-of-range values, and raises
:class:`~ehpss_hil.errors.ConfigError` naming the file and the key path (``events[2].k_loe``).
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from .errors import ConfigError, one_line, show
from .inputfile import load_yaml, parse_yaml
from .limits import MAX_SHOWN_CHARS

__all__ = ["build", "load", "load_yaml", "parse_yaml", "rng"]

T = TypeVar("T")

_MISSING = dataclasses.MISSING


def rng(
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    length: tuple[int, int] | None = None,
    doc: str = "",
    unit: str = "",
    origin: str = "",
) -> dict[str, Any]:
    """Field metadata for a numeric range ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``); for a
    tuple field the range applies to each item and ``length`` bounds the number of items.
    ``unit`` (``"s"``, ``"A"``, ``"1"`` for dimensionless …) and ``origin`` (where the value
    comes from: a derivation, or the measurement that fixed it) document a gate; the loader
    does not use them."""
    return {
        "min": lo,
        "max": hi,
        "lo_open": lo_open,
        "length": length,
        "doc": doc,
        "unit": unit,
        "origin": origin,
    }


def _join(path: str, key: object) -> str:
    """``path`` extended by a list index or a mapping key (a key from a file is shown cut to
    one line: it may be anything YAML allows)."""
    if isinstance(key, int) and not isinstance(key, bool):
        return f"{path}[{key}]"
    name = one_line(str(key), MAX_SHOWN_CHARS)
    return f"{path}.{name}" if path else name


def _type_name(tp: Any) -> str:
    origin = get_origin(tp)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if origin in (Union, types.UnionType):
        return " or ".join(_type_name(a) for a in get_args(tp))
    if origin is tuple:
        return f"a list of {_type_name(get_args(tp)[0])}"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    if tp is type(None):
        return "null"
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(
        tp, getattr(tp, "__name__", str(tp))
    )


def _convert(tp: Any, value: Any, src: str, path: str, meta: dict[str, Any]) -> Any:
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors: list[ConfigError] = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(arg, value, src, path, meta)
            except ConfigError as exc:
                errors.append(exc)
        if len(errors) == 1:
            raise errors[0]
        raise ConfigError(src, path, f"expected {_type_name(tp)}, got {show(value)}")
    if origin is Literal:
        if value not in get_args(tp):
            raise ConfigError(src, path, f"expected {_type_name(tp)}, got {show(value)}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(src, path, f"expected {_type_name(tp)}, got {show(value)}")
        (item_tp, *_rest) = get_args(tp)
        n_min, n_max = meta.get("length") or (0, None)
        if len(value) < n_min or (n_max is not None and len(value) > n_max):
            count = f"{n_min}" if n_min == n_max else f"{n_min} to {n_max}"
            raise ConfigError(src, path, f"expected {count} items, got {len(value)}")
        return tuple(_convert(item_tp, v, src, _join(path, i), meta) for i, v in enumerate(value))
    if dataclasses.is_dataclass(tp):
        return build(typing.cast(type, tp), value, src, path)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(src, path, f"expected true or false, got {show(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(src, path, f"expected an integer, got {show(value)}")
        _check_range(value, src, path, meta)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(src, path, f"expected a number, got {show(value)}")
        try:
            x = float(value)
        except OverflowError:  # an integer beyond any float (10**400)
            x = math.inf
        if not math.isfinite(x):
            raise ConfigError(src, path, f"expected a finite number, got {show(value)}")
        _check_range(x, src, path, meta)
        return x
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(src, path, f"expected a string, got {show(value)}")
        return value
    raise TypeError(f"schema type {tp!r} at {path} is not supported")  # programming error


def _check_range(x: float, src: str, path: str, meta: dict[str, Any]) -> None:
    lo, hi = meta.get("min"), meta.get("max")
    lo_open = meta.get("lo_open", False)
    if lo is not None and (x <= lo if lo_open else x < lo):
        bound = f"> {lo}" if lo_open else f">= {lo}"
        raise ConfigError(src, path, f"expected a value {bound}, got {show(x)}")
    if hi is not None and x > hi:
        raise ConfigError(src, path, f"expected a value <= {hi}, got {show(x)}")


def build(cls: type[T], data: Any, src: str = "", path: str = "") -> T:
    """Build the frozen dataclass ``cls`` from a parsed mapping, validating every key."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(src, path, f"expected a mapping, got {show(data)}")
    hints = get_type_hints(cls)
    fields = {
        f.name: f
        for f in dataclasses.fields(typing.cast(Any, cls))
        if f.init and not f.metadata.get("internal")
    }
    unknown = [k for k in data if k not in fields]
    if unknown:
        known = ", ".join(sorted(fields))
        raise ConfigError(src, _join(path, unknown[0]), f"unknown key (known keys: {known})")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        sub = _join(path, name)
        if name in data:
            kwargs[name] = _convert(hints[name], data[name], src, sub, dict(f.metadata))
        elif f.default is _MISSING and f.default_factory is _MISSING:
            raise ConfigError(src, sub, f"missing required key ({_type_name(hints[name])})")
    try:
        obj = cls(**kwargs)
    except ConfigError as exc:
        if exc.source:
            raise
        raise ConfigError(src, _join(path, exc.key_path) if exc.key_path else path, exc.reason) from exc
    return obj


def load(cls: type[T], path: str | Path, section: str | None = None) -> T:
    """Load ``cls`` from a YAML file (optionally from one top-level ``section`` of it)."""
    data = load_yaml(path)
    if section is not None:
        if not isinstance(data, dict) or section not in data:
            raise ConfigError(str(path), section, "missing required section")
        data = data[section]
    return build(cls, data, str(path))
