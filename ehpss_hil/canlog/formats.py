"""The log formats a logger writes — candump ``-L``, BLF, MF4 — and the writer interface of the
binary ones.

The format comes from ``--log-format`` / ``log.format``, else from the file name (``*.blf``:
BLF, ``*.mf4``: MF4, anything else: candump ``-L``). python-can's :class:`can.LogReader`, and
so ``report`` and ``replay``, pick their reader by the suffix, so a BLF or MF4 log must end in
its suffix and a candump log must not end in one of theirs: a name that disagrees with the
format asked for is refused (:class:`~ehpss_hil.errors.OutputError`, exit 2).

The logger's writer thread (:class:`~ehpss_hil.canlog.writer.CandumpLogger`) writes candump
lines itself (whole lines, rotation by size, a partial line cut back after a failed write); the
binary formats sit behind :class:`FrameFile` (:mod:`~ehpss_hil.canlog.binary`: python-can's
``BLFWriter`` and ``MF4Writer``). Those do not rotate: their file is complete (header, index)
only when it is closed.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Literal, Protocol

from ..errors import OutputError
from .lineformat import FrameItem

LogFormat = Literal["candump", "blf", "mf4"]
#: the formats a logger writes (``--log-format``)
LOG_FORMATS: tuple[LogFormat, ...] = ("candump", "blf", "mf4")
#: the file suffix each binary format needs (python-can picks its reader by it)
BINARY_SUFFIXES: dict[str, LogFormat] = {".blf": "blf", ".mf4": "mf4"}
#: the sidecar's ``format`` value per format (a sidecar with another value is no log of ours)
SIDECAR_FORMATS: dict[LogFormat, str] = {"candump": "candump -L", "blf": "BLF", "mf4": "MF4"}


def log_format(path: str | os.PathLike[str], fmt: str | None = None) -> LogFormat:
    """The format to write ``path`` in: ``fmt`` when given (one of :data:`LOG_FORMATS`; "auto"
    or None: by the suffix), else by the suffix; :class:`OutputError` when the name disagrees
    with ``fmt`` (a reader would pick another format by it)."""
    by_name = BINARY_SUFFIXES.get(Path(path).suffix.lower(), "candump")
    if fmt is None or fmt == "auto":
        return by_name
    if fmt not in LOG_FORMATS:
        raise OutputError(f"{path}: unknown log format {fmt!r} (one of {', '.join(LOG_FORMATS)})")
    if fmt != by_name:
        need = next((s for s, f in BINARY_SUFFIXES.items() if f == fmt), None)
        rule = f"must end in {need}" if need else f"must not end in {Path(path).suffix}"
        raise OutputError(
            f"{path}: log format {fmt}: the name {rule} (python-can and report pick the reader by the suffix)"
        )
    return fmt


def add_log_format_argument(p: argparse.ArgumentParser) -> None:
    """``--log-format {candump,blf,mf4}`` (default: the config's ``log.format``, else the
    suffix) for the processes that log: ``controller``, ``firmware-sim``, ``log``."""
    p.add_argument(
        "--log-format",
        choices=LOG_FORMATS,
        help="log format (default: by the file's suffix, *.blf: blf, *.mf4: mf4, else candump -L); "
        "mf4 needs the 'mf4' extra (asammdf)",
    )


def add_process_log_arguments(p: argparse.ArgumentParser) -> None:
    """``--log``, ``--log-format`` and ``--overwrite`` of the processes that log every frame
    they send and receive (``controller``, ``firmware-sim``)."""
    p.add_argument("--log", help="log of every frame sent and received (candump -L; *.blf: BLF, *.mf4: MF4)")
    add_log_format_argument(p)
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a file at the --log path that is no log of ours (and its numbered files)",
    )


class FrameFile(Protocol):
    """A binary log file the logger's writer thread fills: :meth:`write` a batch of queued
    frames (raises OSError when the file cannot take them), :meth:`close` once (writes what is
    buffered, the header and index, fsyncs; raises OSError on failure)."""

    #: an upper bound of the bytes one frame takes in the file before compression (for the
    #: logger's free-space check)
    frame_bytes: int

    def write(self, batch: Sequence[FrameItem]) -> None: ...

    def close(self) -> None: ...
