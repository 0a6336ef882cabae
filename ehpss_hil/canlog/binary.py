"""BLF and MF4 log files behind :class:`~ehpss_hil.canlog.formats.FrameFile`: python-can's
:class:`can.BLFWriter` and :class:`can.MF4Writer` (MF4 needs ``asammdf``, the ``mf4`` extra).

BLF: each frame goes to python-can's writer (≈ 3 µs a frame), which compresses and writes
128-KiB containers as they fill; :meth:`BlfFile.close` writes the last container and the
header. A BLF whose process was killed holds the containers written so far, with a header that
does not count them.

MF4: python-can's ``MF4Writer.on_message_received`` extends the asammdf file by one record per
call, ≈ 100 µs a frame here — more than a 1 kHz loop's frames leave the writer thread. So
:class:`Mf4File` keeps python-can's file layout (its ``MF4Writer`` builds the groups: data,
error and remote frames, as its ``MF4Reader`` and Vector's tools read them) and appends data
frames :data:`MF4_CHUNK_FRAMES` at a time, one asammdf ``extend`` per chunk (≈ 4 µs a frame);
error and remote frames (rare) go through python-can's own per-frame path. This reads
``MF4Writer``'s ``_mdf``, ``_start_time`` and ``can.io.mf4.STD_DTYPE`` (not python-can's
documented API; ``tests/test_canlog_formats.py`` writes and reads back every frame kind). asammdf
holds the measurement until :meth:`Mf4File.close` saves it: a killed process leaves no MF4.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import can
import numpy as np

from .. import _mf4import
from ..extras import require
from .formats import FrameFile, LogFormat
from .lineformat import FrameItem

#: data frames appended to an MF4 file per asammdf ``extend`` (≈ 4 µs a frame at 256; 32 costs
#: ≈ 18 µs a frame, 1 per call ≈ 100 µs)
MF4_CHUNK_FRAMES = 256
#: bytes one frame takes before compression, at most: BLF object headers (32) + CAN FD message
#: (84); MF4 record (76) + timestamp (8)
FRAME_BYTES_MAX = 128


def enable_mf4(what: str) -> ModuleType:
    """python-can's ``can.io.mf4`` with asammdf (the ``mf4`` extra; ``what`` names the feature
    in the :class:`~ehpss_hil.errors.MissingExtraError` when it is missing). ``import ehpss_hil``
    makes python-can load it with asammdf hidden (:mod:`ehpss_hil._mf4import`), so it is
    executed again here, in its own namespace: its readers and writers, the classes
    ``can.LogReader`` and ``can.Logger`` hold included, then find asammdf."""
    require("mf4", what)
    from can.io import mf4

    if mf4.asammdf is None:
        _mf4import.release()
        importlib.reload(mf4)
    return mf4


def message_of(item: FrameItem) -> can.Message:
    """The :class:`can.Message` of a queued frame tuple (timestamp in s)."""
    ts, can_id, ext, rtr, err, fd, brs, esi, dlc, data = item
    return can.Message(
        timestamp=ts,
        arbitration_id=can_id,
        is_extended_id=ext,
        is_remote_frame=rtr,
        is_error_frame=err,
        is_fd=fd,
        bitrate_switch=brs,
        error_state_indicator=esi,
        dlc=dlc,
        data=data,
        check=False,
    )


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class BlfFile:
    """A BLF log (python-can's :class:`can.BLFWriter`, zlib level 6)."""

    frame_bytes = FRAME_BYTES_MAX

    def __init__(self, path: Path) -> None:
        self.path = path
        self._writer = can.BLFWriter(path)

    def write(self, batch: Sequence[FrameItem]) -> None:
        """Hand every frame of ``batch`` to the writer (a full container is written now)."""
        for item in batch:
            self._writer.on_message_received(message_of(item))

    def close(self) -> None:
        """Write the last container and the header; fsync."""
        self._writer.stop()
        _fsync(self.path)


class Mf4File:
    """An MF4 (ASAM MDF 4.10) log in python-can's layout, data frames appended in chunks."""

    frame_bytes = FRAME_BYTES_MAX

    def __init__(self, path: Path) -> None:
        mf4 = enable_mf4(f"{path}: an MF4 log")
        self.path = path
        self._writer = can.MF4Writer(path)
        self._dtype: np.dtype[Any] = mf4.STD_DTYPE
        self._pending: list[FrameItem] = []

    def write(self, batch: Sequence[FrameItem]) -> None:
        """Queue data frames (appended per :data:`MF4_CHUNK_FRAMES`); error and remote frames
        are appended one by one."""
        for item in batch:
            if item[3] or item[4]:  # remote or error frame
                self._writer.on_message_received(message_of(item))
            else:
                self._pending.append(item)
        if len(self._pending) >= MF4_CHUNK_FRAMES:
            self._append()

    def _append(self) -> None:
        """One asammdf ``extend`` of the pending data frames (group 0: ``CAN_DataFrame``)."""
        items, self._pending = self._pending, []
        if not items:
            return
        rec = np.zeros(len(items), dtype=self._dtype)
        rec["CAN_DataFrame.ID"] = [it[1] for it in items]
        rec["CAN_DataFrame.IDE"] = [it[2] for it in items]
        rec["CAN_DataFrame.Dir"] = 0  # python-can's writer: 0 = received (is_rx)
        rec["CAN_DataFrame.DataLength"] = [len(it[9]) for it in items]
        fd = np.array([it[5] for it in items], dtype=bool)
        rec["CAN_DataFrame.DLC"] = [can.util.len2dlc(it[8]) if it[5] else it[8] for it in items]
        rec["CAN_DataFrame.EDL"] = fd
        rec["CAN_DataFrame.BRS"] = [it[6] and it[5] for it in items]
        rec["CAN_DataFrame.ESI"] = [it[7] and it[5] for it in items]
        data = rec["CAN_DataFrame.DataBytes"]
        for i, it in enumerate(items):
            data[i, : len(it[9])] = np.frombuffer(it[9], dtype=np.uint8)
        w = self._writer
        stamps = np.array([it[0] for it in items], dtype="<f8") - w._start_time
        w.last_timestamp = max(w.last_timestamp, float(items[-1][0]))
        w._mdf.extend(0, [(stamps, None), (rec, None)])

    def close(self) -> None:
        """Append what is pending, save the file (asammdf, compressed), fsync."""
        try:
            self._append()
        finally:
            self._writer.stop()
        _fsync(self.path)


def open_frame_file(path: Path, fmt: LogFormat) -> FrameFile:
    """A new ``fmt`` log at ``path`` (``blf`` or ``mf4``); :class:`MissingExtraError` for MF4
    without asammdf, OSError when the file cannot be created."""
    if fmt == "blf":
        return BlfFile(path)
    if fmt == "mf4":
        return Mf4File(path)
    raise ValueError(f"{fmt!r} is no binary log format")
