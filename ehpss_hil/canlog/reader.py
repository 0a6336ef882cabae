"""Read candump ``-L`` logs back: frames (python-can's reader), DBC-decoded arrays, the sidecar."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import numpy as np

from ..codec import FrameCodec, Verdict
from ..errors import EhpssError
from .sidecar import sidecar_path


class LogError(EhpssError, OSError):
    """A log file or directory cannot be found or read."""

    exit_code = 2


def resolve_log(path: str | os.PathLike[str]) -> Path:
    """A log file itself, or the one ``*.log`` file in a directory (the newest if several)."""
    p = Path(path)
    if p.is_dir():
        logs = sorted(p.glob("*.log"), key=lambda f: f.stat().st_mtime)
        if not logs:
            raise LogError(f"{p}: no *.log file in this directory")
        return logs[-1]
    if not p.exists():
        raise LogError(f"{p}: no such log file")
    return p


def log_files(path: str | os.PathLike[str]) -> list[Path]:
    """The rotation set of ``path``, oldest first: ``path.N`` … ``path.1``, ``path``.

    A path that already ends in ``.N`` stands for itself only.
    """
    p = Path(path)
    suffix = p.name.rsplit(".", 1)[-1]
    if suffix.isdigit():
        return [p]
    numbered = []
    for q in p.parent.glob(p.name + ".*"):
        tail = q.name[len(p.name) + 1:]
        if tail.isdigit():
            numbered.append((int(tail), q))
    return [q for _, q in sorted(numbered, reverse=True)] + ([p] if p.exists() else [])


def read_log(path: str | os.PathLike[str], rotated: bool = True) -> Iterator[can.Message]:
    """Frames of a candump ``-L`` log via :class:`can.io.CanutilsLogReader` (timestamps in s).

    With ``rotated`` the whole rotation set is read, oldest file first.
    """
    files = log_files(path) if rotated else [Path(path)]
    for f in files:
        with can.CanutilsLogReader(f) as reader:
            yield from reader


def read_sidecar(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ``<log>.json`` sidecar of a log, or None when there is none (or it is unreadable)."""
    side = sidecar_path(path)
    try:
        data = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def decode_log(path: str | os.PathLike[str], codec: FrameCodec | None = None,
               rotated: bool = True) -> dict[str, dict[str, np.ndarray]]:
    """Decode a log with the DBC into per-frame-name arrays, in file order.

    Each frame name maps to ``{"t_s": timestamps (s), <signal>: physical values (SI), …}``.
    Kept: frames with a good CRC and plausible values, including those a live receiver would
    drop as WRONG_SEQUENCE (after lost frames the data itself is intact); REPEATED frames and
    bad CRC/DLC/range are left out. ``codec.counts_by_name`` holds every verdict, so rejected
    frames are counted, not hidden. A multiplexed frame (CTRL_INDEX) has one array per signal
    with NaN where a row did not carry it.
    """
    codec = codec if codec is not None else FrameCodec()
    rows: dict[str, list[tuple[float, dict[str, Any]]]] = {}
    for msg in read_log(path, rotated):
        d = codec.classify(msg)
        if d.name is None:
            continue
        values: Any = d.values
        if d.verdict is Verdict.WRONG_SEQUENCE:
            values = codec.message(d.name).decode(bytes(msg.data), decode_choices=False)
        elif not d.verdict.usable:
            continue
        if values is not None:
            rows.setdefault(d.name, []).append((msg.timestamp, values))
    return {name: _to_arrays(r) for name, r in rows.items()}


def _to_arrays(rows: list[tuple[float, dict[str, Any]]]) -> dict[str, np.ndarray]:
    keys: dict[str, None] = {}
    for _, v in rows:
        keys.update(dict.fromkeys(v))
    out: dict[str, np.ndarray] = {"t_s": np.fromiter((t for t, _ in rows), float, len(rows))}
    for k in keys:
        out[k] = np.fromiter((_num(v.get(k, math.nan)) for _, v in rows), float, len(rows))
    return out


def _num(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan
