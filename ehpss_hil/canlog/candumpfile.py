"""The current file of a candump ``-L`` log: unbuffered writes (a failed write is known at
once), cutting a partial line back, and the renames of a rotation (``path`` → ``path.1`` → …).
The :class:`~ehpss_hil.canlog.writer.CandumpLogger` decides what to write and when to rotate.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path


def numbered(path: Path, i: int) -> Path:
    """``run.log``, 3 → ``run.log.3`` (a rotated file)."""
    return path.with_name(f"{path.name}.{i}")


class CandumpFile:
    """``path`` opened for writing (truncated), unbuffered."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fh = open(path, "wb", buffering=0)

    def write_all(self, data: bytes) -> tuple[int, Exception | None]:
        """Write ``data``; (bytes written, the error that stopped it)."""
        view = memoryview(data)
        done = 0
        try:
            while done < len(data):
                n = self._fh.write(view[done:])
                if not n:
                    raise OSError(errno.ENOSPC, "short write")
                done += n
        except (OSError, ValueError) as exc:
            return done, exc
        return done, None

    def cut(self, size: int) -> str | None:
        """Truncate the file to ``size`` bytes (its last complete line) and write on from
        there; the error, if that failed."""
        try:
            os.ftruncate(self._fh.fileno(), size)
            self._fh.seek(size)
        except (OSError, ValueError) as exc:
            return f"cannot cut back a partial line: {exc}"
        return None

    def rotate(self, files: int) -> None:
        """``path.<files-1>`` → ``path.<files>``, …, ``path`` → ``path.1`` (only these: the
        log's own rotated files), then a new empty ``path``. On an OSError ``path`` is reopened
        for appending (writes to it fail and are counted when that fails too) and it is raised."""
        try:
            self._fh.close()
            for i in range(files - 1, 0, -1):
                src = numbered(self.path, i)
                if src.exists():
                    os.replace(src, numbered(self.path, i + 1))
            os.replace(self.path, numbered(self.path, 1))
            self._fh = open(self.path, "wb", buffering=0)
        except OSError:
            try:
                self._fh = open(self.path, "ab", buffering=0)
            except OSError:
                pass
            raise

    def close(self) -> str | None:
        """fsync and close; the first error, if any."""
        error = None
        try:
            os.fsync(self._fh.fileno())
        except (OSError, ValueError) as exc:
            error = str(exc)
        try:
            self._fh.close()
        except OSError as exc:
            error = error or str(exc)
        return error
