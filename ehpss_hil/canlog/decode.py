"""A log decoded with the DBC into per-frame-name columns, streamed frame by frame.

:func:`decode_log` never holds more than one frame of the file as Python objects: each decoded
frame is appended to compact float64 columns (:class:`Columns`, 8 bytes per value), the log's
time order is checked on the way through a bounded window (:class:`~.order.TimeOrder`: a file
out of time order is one line, not a sort in memory), and a log with more than ``max_values``
decoded values is refused with one line before its columns grow further
(:data:`~ehpss_hil.limits.MAX_LOG_VALUES`).
"""

from __future__ import annotations

import math
import os
from array import array
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..codec import FrameCodec, Verdict
from ..limits import MAX_LOG_VALUES
from .files import LogError
from .order import TimeOrder
from .reader import FRAME_INDEX, BadLines, read_frames

#: decoded values per 1 kHz controller cycle of a bench log (for the message only)
_VALUES_PER_BENCH_CYCLE = 49


class TooLongError(LogError):
    """A log holds more frames or samples than a report lays out in memory."""


class Columns:
    """One frame name's decoded rows as float64 columns; a signal a row does not carry (a
    multiplexed frame) is NaN there."""

    def __init__(self) -> None:
        self.n = 0
        #: values held (rows × columns, NaN fill included)
        self.cells = 0
        self.cols: dict[str, array[float]] = {"t_s": array("d")}

    def add(self, t_s: float, values: dict[str, Any]) -> None:
        """Append one row: timestamp (s) and the decoded signal values."""
        cols = self.cols
        cols["t_s"].append(t_s)
        for k, v in values.items():
            col = cols.get(k)
            if col is None:
                col = cols[k] = array("d", [math.nan]) * self.n
            col.append(_num(v))
        self.n += 1
        self.cells = self.n * len(cols)
        for col in cols.values():
            if len(col) < self.n:
                col.append(math.nan)

    def arrays(self) -> dict[str, np.ndarray]:
        """The columns as numpy arrays (the ``array`` buffers are released)."""
        out = {}
        for k in list(self.cols):
            out[k] = np.frombuffer(self.cols.pop(k), dtype=np.float64).copy()
        return out


def _num(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def decode_log(
    path: str | os.PathLike[str],
    codec: FrameCodec | None = None,
    rotated: bool = True,
    bad: BadLines | None = None,
    order: bool = False,
    max_values: int = MAX_LOG_VALUES,
) -> dict[str, dict[str, np.ndarray]]:
    """Decode a log (any format :func:`~.reader.read_frames` reads) with the DBC into
    per-frame-name arrays, in file order.

    Each frame name maps to ``{"t_s": timestamps (s), <signal>: physical values (SI), …}``.
    Kept: frames with a good CRC and plausible values, including those a live receiver would
    drop as WRONG_SEQUENCE (after lost frames the data itself is intact); REPEATED frames and
    bad CRC/DLC/range are left out. ``codec.counts_by_name`` holds every verdict, so rejected
    frames are counted, not hidden. A multiplexed frame (CTRL_INDEX) has one array per signal
    with NaN where a row did not carry it. Lines that are no frame are counted in ``bad``.
    With ``order`` each name also has :data:`FRAME_INDEX`: the frame's position among all the
    frames of the log (0, 1, … in file order), which tells in what order frames of different
    names were logged whatever their timestamps say.

    A log whose lines are not in time order beyond the reorder window is an
    :class:`~.order.OutOfOrderError`; one with more than ``max_values`` decoded values
    (:attr:`Columns.cells`) a
    :class:`TooLongError` (both one line, exit 2).
    """
    codec = codec if codec is not None else FrameCodec()
    p = Path(path)
    rows: dict[str, Columns] = {}
    held = 0
    for i, name, t_s, values in decoded_frames(path, codec, bad, rotated):
        if order:
            values = {**values, FRAME_INDEX: i}
        cols = rows.setdefault(name, Columns())
        held -= cols.cells
        cols.add(t_s, values)
        held += cols.cells
        if held > max_values:
            raise TooLongError(
                f"{p}: too long to report: more than {max_values} decoded signal values (about "
                f"{max_values // _VALUES_PER_BENCH_CYCLE} controller cycles of a bench log; a report "
                "holds every sample in memory): cut the log (candump lines stand alone: head -n)"
            )
    return {name: c.arrays() for name, c in rows.items()}


def decoded_frames(
    path: str | os.PathLike[str], codec: FrameCodec, bad: BadLines | None = None, rotated: bool = True
) -> Iterator[tuple[int, str, float, dict[str, Any]]]:
    """``(position in the file, frame name, timestamp (s), decoded values)`` of every frame of
    a log that :func:`decode_log` keeps (its docstring), streamed; the time order is checked
    through the bounded reorder window on the way."""
    timeline: TimeOrder[None] = TimeOrder(Path(path))
    for i, msg in enumerate(read_frames(path, bad, rotated)):
        timeline.push(msg.timestamp, None)
        d = codec.classify(msg)
        if d.name is None:
            continue
        values: Any = d.values
        if d.verdict is Verdict.WRONG_SEQUENCE:
            values = codec.message(d.name).decode(bytes(msg.data), decode_choices=False)
        elif not d.verdict.usable:
            continue
        if values is not None:
            yield i, d.name, msg.timestamp, values
