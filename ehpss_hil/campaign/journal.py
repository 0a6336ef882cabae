"""The journal of finished runs: one JSON line per run, appended as each run finishes.

Only the campaign's main process writes it, each record with one ``write`` of a whole line on a
file opened with ``O_APPEND``: a process killed at any instant leaves every earlier line whole (the
kernel holds what was written; :meth:`Journal.close` syncs it to disk). A torn last line (a machine
that lost power mid-write) is cut off when the journal is opened again, and lines that do not parse
are ignored, so a resumed campaign simply runs those again. An exclusive ``flock`` keeps a second
campaign from writing into the same directory at the same time.

Floats go through JSON unchanged (``repr`` round-trips; inf and NaN as ``Infinity``/``NaN``).
"""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path
from typing import Any

from ..errors import OutputError

JOURNAL_NAME = "runs.jsonl"


def read_journal(path: Path) -> dict[str, dict[str, Any]]:
    """The whole records in ``path`` by run hash (none when it does not exist)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return {}
    except OSError as exc:
        raise OutputError(f"cannot read {path}: {exc.strerror or exc}") from exc
    out: dict[str, dict[str, Any]] = {}
    for line in data.split(b"\n")[:-1]:  # the part after the last newline is no whole record
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        if (
            isinstance(rec, dict)
            and isinstance(rec.get("run_hash"), str)
            and isinstance(rec.get("metrics"), dict)
        ):
            out[rec["run_hash"]] = rec
    return out


class Journal:
    """The journal file of a campaign directory, open for appending (locked while open)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self._fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise OutputError(f"cannot open {path}: {exc.strerror or exc}") from exc
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(self._fd)
            raise OutputError(f"{path} is in use by another campaign") from exc
        self._cut_torn_tail()

    def _cut_torn_tail(self) -> None:
        size = os.fstat(self._fd).st_size
        if size == 0:
            return
        tail = os.pread(self._fd, min(size, 1 << 20), max(0, size - (1 << 20)))
        if tail.endswith(b"\n"):
            return
        cut = tail.rfind(b"\n")
        os.ftruncate(self._fd, size - len(tail) + cut + 1 if cut >= 0 else max(0, size - len(tail)))

    def append(self, record: dict[str, Any]) -> None:
        """Append ``record`` as one line (one write)."""
        line = (json.dumps(record, separators=(",", ":")) + "\n").encode()
        try:
            os.write(self._fd, line)
        except OSError as exc:
            raise OutputError(f"cannot write {self.path}: {exc.strerror or exc}") from exc

    def close(self) -> None:
        """Sync to disk, unlock and close."""
        try:
            os.fsync(self._fd)
        finally:
            os.close(self._fd)

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
