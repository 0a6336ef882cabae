"""Read logs back: frames, DBC-decoded arrays, the sidecar — one path for every format.

:func:`read_frames` is the one reader ``report`` and ``replay`` use: candump ``-L`` files
(``*.log`` and their rotation sets) are parsed as python-can's
:class:`can.io.CanutilsLogReader` parses them (same messages), but a line that is not a whole
frame line — garbage, or a last line without its newline (a process killed while writing, a
disk that filled up) — is skipped and counted in :class:`BadLines` instead of ending the read
with a ValueError; every other format python-can reads (``.asc``, ``.blf``, ``.trc``, ``.csv``,
``.mf4`` with asammdf, …) goes through :func:`can.LogReader`.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can

from .files import LogError, check_regular, open_log, read_json_capped
from .lineformat import CAN_ERR_BUSERROR, CAN_ERR_FLAG
from .sidecar import sidecar_path

#: ``(sec.usec) iface ID#DATA`` | ``ID#R[dlc]`` | ``ID##<flags>DATA`` (candump -L), optional R/T
_LINE = re.compile(
    r"\((\d+\.\d+)\) (\S+) ([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#"
    r"(R\d?|#[0-9A-Fa-f](?:[0-9A-Fa-f]{2}){0,64}|(?:[0-9A-Fa-f]{2}){0,8})"
    r"(?: [RrTt])?"
)


#: characters of a bad line shown in :class:`BadLines` (anything but printable ASCII as ``?``)
_SHOWN_CHARS = 40


@dataclass
class BadLines:
    """Lines of a log that are no frame line: skipped, counted, the first few kept for the
    message (``file:line: text``, printable ASCII only: a binary file shows as ``?``)."""

    count: int = 0
    examples: list[str] = field(default_factory=list)

    def add(self, path: Path, number: int, line: str) -> None:
        """Count one bad line (number ``number`` of ``path``)."""
        self.count += 1
        if len(self.examples) < 3:
            shown = "".join(c if " " <= c <= "~" else "?" for c in line.rstrip()[:_SHOWN_CHARS])
            self.examples.append(f"{path.name}:{number}: {shown!r}")

    def text(self) -> str:
        """``2 bad lines skipped (bus.log:7: '(16…')``, or empty when there were none."""
        if not self.count:
            return ""
        return f"{self.count} bad line(s) skipped ({'; '.join(self.examples)})"


def parse_line(line: str) -> can.Message | None:
    """The frame of one ``candump -L`` line (with its newline), or None when it is none."""
    if not line.endswith("\n"):
        return None  # a cut last line could still match, with fewer data bytes
    m = _LINE.fullmatch(line.rstrip("\r\n"))
    if m is None:
        return None
    ts, chan, ident, body = m.group(1), m.group(2), m.group(3), m.group(4)
    can_id = int(ident, 16)
    if can_id & CAN_ERR_FLAG and can_id & CAN_ERR_BUSERROR:
        return can.Message(timestamp=float(ts), is_error_frame=True)
    fd = body.startswith("#")
    flags = int(body[1], 16) if fd else 0
    data = body[2:] if fd else body
    remote = data[:1] in ("R", "r")
    try:
        return can.Message(
            timestamp=float(ts),
            arbitration_id=can_id & 0x1FFFFFFF,
            is_extended_id=len(ident) > 3,
            is_remote_frame=remote,
            is_fd=fd,
            bitrate_switch=bool(flags & 1),
            error_state_indicator=bool(flags & 2),
            dlc=int(data[1:] or 0) if remote else len(data) // 2,
            data=None if remote else bytes.fromhex(data),
            channel=int(chan) if chan.isdigit() else chan,
            check=True,
        )
    except ValueError:
        return None


#: the key :func:`decode_log` adds with ``order``: a frame's position in the log (file order)
FRAME_INDEX = "frame_index"


#: suffixes of the logs python-can's :func:`can.LogReader` reads besides candump ``.log``
#: (looked for in a directory that holds no ``*.log``)
OTHER_LOG_SUFFIXES = (".asc", ".blf", ".trc", ".mf4")


def resolve_log(path: str | os.PathLike[str]) -> Path:
    """A log file itself, or the log in a directory: the newest ``*.log``, else the newest file
    with one of :data:`OTHER_LOG_SUFFIXES`."""
    p = Path(path)
    if p.is_dir():
        logs = sorted((f for f in p.glob("*.log") if f.is_file()), key=lambda f: f.stat().st_mtime)
        if not logs:
            logs = sorted(
                (f for f in p.iterdir() if f.suffix.lower() in OTHER_LOG_SUFFIXES and f.is_file()),
                key=lambda f: f.stat().st_mtime,
            )
        if not logs:
            raise LogError(f"{p}: no *.log (or {', '.join(OTHER_LOG_SUFFIXES)}) file in this directory")
        return logs[-1]
    if not p.exists():
        raise LogError(f"{p}: no such log file")
    return check_regular(p)


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
        tail = q.name[len(p.name) + 1 :]
        if tail.isdigit():
            numbered.append((int(tail), q))
    return [q for _, q in sorted(numbered, reverse=True)] + ([p] if p.exists() else [])


def read_log(
    path: str | os.PathLike[str], rotated: bool = True, bad: BadLines | None = None
) -> Iterator[can.Message]:
    """Frames of a candump ``-L`` log (timestamps in s), as python-can's reader gives them.

    With ``rotated`` the whole rotation set is read, oldest file first. Lines that are no frame
    are skipped and counted in ``bad``. Each file is read up to the size it had when it was
    opened (a log still being written: the lines written so far), and only a regular file is
    read (a FIFO or a device is a :class:`LogError`).
    """
    files = log_files(path) if rotated else [Path(path)]
    bad = bad if bad is not None else BadLines()
    for f in files:
        fh, size = open_log(f)
        with fh:
            left = size
            for number, raw in enumerate(fh, start=1):
                if left <= 0:
                    break
                left -= len(raw)
                line = raw[: len(raw) + min(left, 0)].decode("ascii", errors="replace")
                if not line.strip():
                    continue
                msg = parse_line(line)
                if msg is None:
                    bad.add(f, number, line)
                    continue
                yield msg


def is_candump(path: str | os.PathLike[str]) -> bool:
    """A candump ``-L`` log by its name: ``*.log`` or a rotated ``*.log.N``."""
    parts = Path(path).name.split(".")
    return len(parts) > 1 and (parts[-1] == "log" or (parts[-1].isdigit() and "log" in parts))


def read_frames(
    path: str | os.PathLike[str], bad: BadLines | None = None, rotated: bool = True
) -> Iterator[can.Message]:
    """The frames of any log python-can reads, in file order (timestamps in s): candump ``-L``
    files (``*.log``; with ``rotated`` the whole rotation set) through :func:`read_log`, every
    other format (``.asc``, ``.blf``, ``.csv``, ``.trc``, …) through :class:`can.LogReader`. A
    file python-can cannot read, or whose data its reader rejects, is a :class:`LogError` (one
    line), never a traceback."""
    if is_candump(path):
        yield from read_log(path, rotated, bad)
        return
    p = check_regular(path)
    if p.suffix.lower() == ".mf4":
        from .binary import enable_mf4

        enable_mf4(f"{p}: reading an MF4 log")
    try:
        reader = can.LogReader(p)
    except Exception as exc:  # a foreign file: unknown suffix, or a header its reader rejects
        raise LogError(f"{p}: not a log python-can reads ({type(exc).__name__}: {exc})") from exc
    try:
        yield from reader
    except Exception as exc:  # a foreign file: whatever its reader raises is bad input
        raise LogError(f"{p}: unreadable {p.suffix or 'log'} data ({type(exc).__name__}: {exc})") from exc
    finally:
        reader.stop()


def read_sidecar(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ``<log>.json`` sidecar of a log, or None when there is none (or it is no JSON
    object); a sidecar that is no regular file, too large or too deep is a :class:`LogError`
    (:func:`~ehpss_hil.canlog.files.read_json_capped`)."""
    return read_json_capped(sidecar_path(path))
