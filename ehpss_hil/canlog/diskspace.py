"""Disk space for candump logs: a reserve kept free, and lines that could not be written.

A log that fills its file system would leave no room for what a process writes when it ends
(the log's final sidecar, the exit summary, ``run.json``, ``metrics.json``). :class:`DiskRoom`
says whether a chunk of lines still fits above :data:`DISK_RESERVE_BYTES` of free space;
:class:`LineDrops` counts the lines that were not written, by reason, and warns once, then at
most every :attr:`LineDrops.WARN_INTERVAL_S` with the running count.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

_log = logging.getLogger("ehpss_hil.canlog")

#: free space (bytes) a log leaves on its file system for the files written at exit
DISK_RESERVE_BYTES = 64 * 1024
#: how often (s) free space is asked of the kernel while it is plentiful
_STATVFS_PERIOD_S = 1.0


class DiskRoom:
    """Free space on the file system of ``directory``, as the writer thread sees it.

    ``statvfs`` is asked at most every second while at least twice the reserve plus the chunk is
    free; closer to the reserve it is asked for every chunk (a few µs)."""

    def __init__(self, directory: Path, reserve_bytes: int = DISK_RESERVE_BYTES) -> None:
        self.directory = directory
        self.reserve_bytes = reserve_bytes
        self._free = 0
        self._asked_s = -1e9

    def free_bytes(self) -> int:
        """Bytes an unprivileged writer may still use (``f_bavail``); a huge number when the
        file system does not say."""
        try:
            st = os.statvfs(self.directory)
        except OSError:
            return 2**62
        return st.f_bavail * st.f_frsize

    def fits(self, nbytes: int) -> bool:
        """True when ``nbytes`` more leave at least the reserve free."""
        now = time.monotonic()
        if self._free < 2 * self.reserve_bytes + nbytes or now - self._asked_s > _STATVFS_PERIOD_S:
            self._free = self.free_bytes()
            self._asked_s = now
        if self._free - nbytes < self.reserve_bytes:
            return False
        self._free -= nbytes
        return True


class LineDrops:
    """Lines not written, by reason (``queue full``, ``after close``, ``disk full``,
    ``write error``); warnings for the disk/write ones: the first at once, then at most one
    every :attr:`WARN_INTERVAL_S` seconds with the running count."""

    WARN_INTERVAL_S = 10.0

    def __init__(self, path: Path) -> None:
        self.path = path
        self.by_reason: dict[str, int] = {}
        self._next_warn_s = 0.0
        self.failing = False

    @property
    def total(self) -> int:
        """All lines not written."""
        return sum(self.by_reason.values())

    def add(self, reason: str, lines: int, detail: str = "") -> None:
        """Count ``lines`` not written for ``reason`` (warn about disk/write failures)."""
        if lines <= 0:
            return
        self.by_reason[reason] = self.by_reason.get(reason, 0) + lines
        if reason not in ("disk full", "write error"):
            return
        self.failing = True
        now = time.monotonic()
        if now >= self._next_warn_s:
            self._next_warn_s = now + self.WARN_INTERVAL_S
            _log.warning(
                "candump log %s: cannot write (%s%s): %d lines dropped so far; "
                "control continues, the count goes to the sidecar",
                self.path,
                reason,
                f": {detail}" if detail else "",
                self.by_reason[reason],
            )

    def resumed(self) -> None:
        """Lines are written again after a failure: say so once."""
        if self.failing:
            self.failing = False
            _log.warning("candump log %s: writing again (%d lines dropped so far)", self.path, self.total)
