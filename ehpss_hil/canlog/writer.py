"""Non-blocking CAN log writer: bounded queue, one writer thread, size rotation, sidecar.

It writes candump ``-L`` (the default), BLF or MF4 (:mod:`~ehpss_hil.canlog.formats`: from the
``fmt`` asked for, else the file's suffix). Everything below holds for every format but
rotation, which is candump's only: a BLF or MF4 file is complete only when closed (header,
index), so it never rotates (``backups`` is 0 for them); their frames are written through
:class:`~ehpss_hil.canlog.formats.FrameFile` (python-can's writers).

The caller's hot path (:meth:`CandumpLogger.log`) only appends a small tuple to a bounded deque;
formatting, writing and rotating happen in one writer thread. When the queue is full the line is
counted as dropped (never blocked on, never silently lost): the count is in the sidecar and in the
:class:`LogSummary` that :meth:`CandumpLogger.close` returns.

A full disk does not stop the caller either. The writer leaves ``disk_reserve_bytes`` free on the
file system (for the sidecar and the files a process writes when it ends) and drops lines beyond
that; a write that fails anyway (ENOSPC, EIO) is cut back to the last complete line, so a reader
never sees half a line. Both are counted by reason, warned about once and then every 10 s with
the running count, and the logger closes cleanly (the sidecar keeps room for its own updates).

Line format: :mod:`~ehpss_hil.canlog.lineformat` (exactly ``candump -L``'s). No comments and no
header: every file of a rotation set is a standalone log that ``canplayer``, ``cantools decode``
and python-can's reader accept.

Real-time note: the writer thread holds the GIL while it formats a batch (at most
``_BATCH_LINES`` lines, ≈ 50–100 µs) and yields it after each batch. Woken by its 20 ms poll it
would do so at a random moment, often in the middle of a loop cycle, which then waits for the
GIL. A loop calls :meth:`CandumpLogger.kick` when a cycle is done: the writer then formats the
queued lines while the loop sleeps, and its poll rarely fires.
"""

from __future__ import annotations

import atexit
import errno
import logging
import os
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import can

from ..extras import require
from .candumpfile import CandumpFile, numbered
from .diskspace import DISK_RESERVE_BYTES, DiskRoom, LineDrops
from .formats import SIDECAR_FORMATS, FrameFile, log_format
from .lineformat import MAX_LINE_BYTES, FrameItem, format_line
from .sidecar import (
    SIDECAR_RESERVE_BYTES,
    FileRecord,
    build_sidecar,
    claim_log_names,
    sidecar_path,
    write_json_atomic,
)
from .summary import LogSummary

_log = logging.getLogger(__name__)

_BATCH_LINES = 32  # ≈ 50 µs of formatting per GIL hold
_KICK_LINES = 32  # kick() wakes the writer once this many lines are queued
_POLL_S = 0.02


class CandumpLogger:
    """Log CAN frames to ``path`` without ever blocking the caller: in ``candump -L`` format,
    or BLF or MF4 (``fmt``: ``candump``, ``blf``, ``mf4``; None: by the suffix, ``*.blf``,
    ``*.mf4``, else candump; a name that disagrees with ``fmt`` is an OutputError).

    ``max_bytes``: rotate before a file would exceed this size (``run.log`` → ``run.log.1`` …,
    whole lines only); ``backups``: rotated files kept (0: never rotate, like
    :class:`logging.handlers.RotatingFileHandler`). ``queue_lines``: queue bound (frames).
    ``sidecar``: caller metadata for ``<path>.json`` (e.g. ``config``, ``scenario``, ``dbc``
    (path, hashed here), ``clock`` (a description of where ``msg.timestamp`` comes from)).

    ``disk_reserve_bytes``: free space left on the file system (see the module docstring).

    Opening replaces only a log this class wrote (:mod:`ehpss_hil.outputs`: the sidecar
    ``path.json`` names the log and its rotated files): it truncates ``path`` and removes the
    rotated files that sidecar lists. Any other existing ``path``, ``path.json`` or ``path.1`` …
    ``path.<backups>`` is refused (:class:`~ehpss_hil.errors.OutputError`) unless
    ``overwrite``, which replaces those names only; rotation moves and deletes only files of
    this log. It raises OSError when the log or its sidecar cannot be written (a read-only or
    full folder), leaving no file it created behind.
    :meth:`log` may be called from any thread; :meth:`close` is idempotent and safe to call from
    a signal handler of the owning process (it also runs at interpreter exit).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        iface: str = "can0",
        max_bytes: int = 256 * 2**20,
        backups: int = 5,
        queue_lines: int = 200_000,
        sidecar: dict[str, Any] | None = None,
        disk_reserve_bytes: int = DISK_RESERVE_BYTES,
        overwrite: bool = False,
        fmt: str | None = None,
    ) -> None:
        self.format = log_format(path, fmt)
        if self.format != "candump":
            backups = 0  # a binary log is complete only when closed: no rotation
        if not iface or any(c.isspace() for c in iface):
            raise ValueError(f"iface must be a non-empty name without spaces, got {iface!r}")
        if max_bytes < 4 * MAX_LINE_BYTES:
            raise ValueError(f"max_bytes must be >= {4 * MAX_LINE_BYTES}")
        if backups < 0 or queue_lines < 1:
            raise ValueError("backups must be >= 0 and queue_lines >= 1")
        self.path = Path(path)
        self.iface = iface
        self.max_bytes = int(max_bytes)
        self.backups = int(backups)
        self.queue_lines = int(queue_lines)
        self._queue: deque[FrameItem] = deque()
        self._written = 0
        self._overflow = 0  # queue full
        self._late = 0  # logged after close
        self._discarded = 0
        self._error: str | None = None
        self._drop_lock = threading.Lock()
        self._close_lock = threading.RLock()
        self._stop = threading.Event()
        self._kick = threading.Lock()  # held: no kick pending; kick() releases, the writer takes
        self._kick.acquire()
        self._closed = False
        self._summary: LogSummary | None = None
        self._records: list[FileRecord] = [FileRecord()]  # [0] = current file, [i] = path.i
        if self.format == "mf4":
            require("mf4", f"{self.path}: an MF4 log")  # before any file is touched
        claim_log_names(self.path, self.backups, f"a {self.format} log", overwrite)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._room = DiskRoom(self.path.parent, disk_reserve_bytes)
        self._drops = LineDrops(self.path)
        existed = self.path.exists()
        self._fh: CandumpFile | None = None
        self._binary: FrameFile | None = None
        if self.format == "candump":
            self._fh = CandumpFile(self.path)
        else:
            from .binary import open_frame_file  # python-can's binary writers, asammdf for MF4

            self._binary = open_frame_file(self.path, self.format)
        self._file_open = True
        self._meta = build_sidecar(self.path, iface, sidecar, max_bytes, backups, queue_lines)
        self._meta["format"] = SIDECAR_FORMATS[self.format]
        try:
            self._write_sidecar("open", strict=True)
        except OSError:
            self._close_file()
            if not existed:
                self.path.unlink(missing_ok=True)
            raise
        self._thread = threading.Thread(target=self._run, name=f"canlog:{self.path.name}", daemon=True)
        self._thread.start()
        atexit.register(self.close)

    # ---- producer side -------------------------------------------------------------------
    def log(self, msg: can.Message) -> None:
        """Queue one frame (timestamp: ``msg.timestamp``, s). Never blocks; counts overflow."""
        if self._closed or len(self._queue) >= self.queue_lines:
            with self._drop_lock:
                if self._closed:
                    self._late += 1
                else:
                    self._overflow += 1
            return
        self._queue.append(
            (
                msg.timestamp or 0.0,
                msg.arbitration_id,
                msg.is_extended_id,
                msg.is_remote_frame,
                msg.is_error_frame,
                msg.is_fd,
                msg.bitrate_switch,
                msg.error_state_indicator,
                msg.dlc,
                bytes(msg.data),
            )
        )

    def kick(self) -> None:
        """The caller is about to be idle (a loop between cycles): wake the writer now when at
        least ``_KICK_LINES`` frames are queued, so it formats them while the caller sleeps."""
        if len(self._queue) >= _KICK_LINES and self._kick.locked():
            self._release_kick()

    def _release_kick(self) -> None:
        try:
            self._kick.release()
        except RuntimeError:  # released meanwhile from another thread (close)
            pass

    def note(self, key: str, value: object) -> None:
        """Add ``key: value`` to the sidecar (written with the next update, at the latest when
        the log is closed); for counts the caller keeps (e.g. rejected datagrams)."""
        self._meta[key] = value

    def __call__(self, msg: can.Message) -> None:
        """Same as :meth:`log` (so the logger can be a python-can Notifier listener callable)."""
        self.log(msg)

    @property
    def written(self) -> int:
        """Frames written to disk so far."""
        return self._written

    @property
    def dropped(self) -> int:
        """Frames not written: queue full, logged after close, no disk space or a write error."""
        return self._overflow + self._late + self._drops.total

    def dropped_by_reason(self) -> dict[str, int]:
        """:attr:`dropped` by reason (reasons with a count only)."""
        out = {"queue full": self._overflow, "after close": self._late, **self._drops.by_reason}
        return {k: n for k, n in out.items() if n}

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has started."""
        return self._closed

    # ---- writer thread -------------------------------------------------------------------
    def _run(self) -> None:
        q = self._queue
        while True:
            if not q:
                if self._stop.is_set():
                    return
                self._kick.acquire(timeout=_POLL_S)  # a kick, close() or the poll period
                continue
            n = min(len(q), _BATCH_LINES)
            batch = [q.popleft() for _ in range(n)]
            self._write_batch(batch)
            time.sleep(0)  # hand the GIL to a waiting real-time thread

    def _write_batch(self, batch: list[FrameItem]) -> None:
        """Write whole lines; rotate first whenever the next line would overflow the file."""
        if self._binary is not None:
            self._write_frames(self._binary, batch)
            return
        rec = self._records[0]
        chunk: list[bytes] = []
        size = rec.bytes
        start = 0
        for i, item in enumerate(batch):
            line = format_line(item, self.iface).encode("ascii")
            if self.backups > 0 and size + len(line) > self.max_bytes and size > 0:
                self._flush_chunk(chunk, batch[start:i])
                self._rotate()
                chunk, size, start = [], 0, i
            chunk.append(line)
            size += len(line)
        self._flush_chunk(chunk, batch[start:])

    def _flush_chunk(self, chunk: list[bytes], items: list[FrameItem]) -> None:
        """Write whole lines: beyond the disk reserve none, after a failed write those that
        were written completely (the file is cut back to its last newline)."""
        if not chunk:
            return
        data = b"".join(chunk)
        if not self._room.fits(len(data)):
            kept = f"{self._room.reserve_bytes // 1024} KiB kept free"
            self._error = f"disk full: {kept}"
            self._drops.add("disk full", len(chunk), kept)
            return
        assert self._fh is not None
        done, exc = self._fh.write_all(data)
        keep = done if exc is None else data.rfind(b"\n", 0, done) + 1
        rec = self._records[0]
        if keep < done:
            self._error = self._fh.cut(rec.bytes + keep) or self._error
        lines = len(chunk) if exc is None else data.count(b"\n", 0, keep)
        if lines:
            rec.add(lines, keep, items[0][0], items[lines - 1][0])
            self._written += lines
        if exc is None:
            self._drops.resumed()
            return
        self._error = str(exc)
        full = isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)
        self._drops.add("disk full" if full else "write error", len(chunk) - lines, str(exc))

    def _write_frames(self, out: FrameFile, batch: list[FrameItem]) -> None:
        """Hand a batch to a binary log; beyond the disk reserve, or when the file fails, its
        frames are dropped and counted (a failed batch may be written in part)."""
        if not self._room.fits(len(batch) * out.frame_bytes):
            kept = f"{self._room.reserve_bytes // 1024} KiB kept free"
            self._error = f"disk full: {kept}"
            self._drops.add("disk full", len(batch), kept)
            return
        try:
            out.write(batch)
        except (OSError, ValueError) as exc:
            self._error = str(exc)
            full = isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)
            self._drops.add("disk full" if full else "write error", len(batch), str(exc))
            return
        self._records[0].add(len(batch), 0, batch[0][0], batch[-1][0])
        self._written += len(batch)
        self._drops.resumed()

    def _rotate(self) -> None:
        """``path`` → ``path.1`` → … → ``path.<backups>``; the oldest beyond that is deleted."""
        assert self._fh is not None
        try:  # only this log's rotated files move: path.1 … path.<len(records) - 1>
            self._fh.rotate(min(len(self._records), self.backups))
        except OSError as exc:
            self._error = f"rotation failed: {exc}"
            return
        self._records.insert(0, FileRecord())
        while len(self._records) > self.backups + 1:
            self._discarded += self._records.pop().lines
        self._write_sidecar("open")

    # ---- shutdown ------------------------------------------------------------------------
    def close(self) -> LogSummary:
        """Flush every queued line, join the writer, fsync, finalize the sidecar (idempotent).

        Returns the :class:`LogSummary`; logs a warning when frames were dropped.
        """
        with self._close_lock:
            if self._summary is not None:
                return self._summary
            self._closed = True
            self._stop.set()
            if self._kick.locked():
                self._release_kick()
            self._thread.join()
            if self._summary is not None:  # a re-entrant call (signal handler) finished it
                return self._summary
            leftover = len(self._queue)
            self._queue.clear()
            with self._drop_lock:
                self._late += leftover
            self._close_file()
            summary = LogSummary(
                str(self.path),
                self._written,
                self.dropped,
                self._discarded,
                [str(self._file_name(i)) for i in range(len(self._records) - 1, -1, -1)],
                self._error,
                self.dropped_by_reason(),
            )
            self._write_sidecar("closed")
            self._summary = summary
            atexit.unregister(self.close)
        if summary.dropped:
            _log.warning("%s log %s", self.format, summary)
        return summary

    def _close_file(self) -> None:
        if not self._file_open:
            return
        self._file_open = False
        if self._binary is not None:
            try:
                self._binary.close()
                self._records[0].bytes = self.path.stat().st_size
            except (OSError, ValueError) as exc:
                self._error = self._error or f"cannot finish the {self.format} file: {exc}"
            return
        if self._fh is not None:
            error = self._fh.close()  # closed whatever failed before (a full disk)
            self._error = self._error or error

    def _file_name(self, i: int) -> Path:
        return self.path if i == 0 else numbered(self.path, i)

    def _write_sidecar(self, status: str, strict: bool = False) -> None:
        """Write the sidecar (keeping room for its later updates); an error is raised when
        ``strict``, else recorded in :attr:`LogSummary.error`."""
        self._meta["status"] = status
        self._meta["counts"] = {
            "written": self._written,
            "dropped": self.dropped,
            "discarded_by_rotation": self._discarded,
        }
        if self.dropped:
            self._meta["counts"]["dropped_by_reason"] = self.dropped_by_reason()
        self._meta["files"] = [
            rec.as_dict(self._file_name(i).name) for i, rec in reversed(list(enumerate(self._records)))
        ]
        self._meta["error"] = self._error
        if status == "closed":
            self._meta["end_time_s"] = time.time()
        try:
            write_json_atomic(sidecar_path(self.path), self._meta, SIDECAR_RESERVE_BYTES)
        except OSError as exc:
            if strict:
                raise
            self._error = self._error or f"sidecar: {exc}"

    def __enter__(self) -> CandumpLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
