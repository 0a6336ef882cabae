"""The journal of finished runs: one JSON line per run, appended as each run finishes.

Only the campaign's main process writes it, each record with one ``write`` of a whole line on a
file opened with ``O_APPEND``: a process killed at any instant leaves every earlier line whole (the
kernel holds what was written; :meth:`Journal.close` syncs it to disk). A torn last line (a machine
that lost power mid-write) is cut off when the journal is opened again, so a resumed campaign simply
runs that run again. An exclusive ``flock`` keeps a second campaign from writing into the same
directory at the same time.

The journal is input like any file a user can edit: it is read line by line (at most
:data:`MAX_RECORD_BYTES` a line, only the records of planned runs kept), a symlink is refused, and a
whole line that is no record of ours — not JSON, another index for its run, a metric missing, extra
or not a number — is an :class:`~ehpss_hil.errors.OutputError` naming the line (exit 2): delete it
and ``--resume`` runs that run again. A record of a run the campaign does not plan (an earlier draw
of the file) is skipped.

Floats go through JSON unchanged (``repr`` round-trips; inf and NaN as ``Infinity``/``NaN``).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import OutputError

JOURNAL_NAME = "runs.jsonl"
#: longest journal line read (bytes): a run's record is about 1 kB per mode
MAX_RECORD_BYTES = 64 * 1024
_OPEN_FLAGS = os.O_NOFOLLOW | os.O_CLOEXEC


@dataclass(frozen=True)
class Expected:
    """What the records of a campaign hold: run hash → run index, and the metric columns."""

    index: Mapping[str, int]
    columns: Collection[str]


def _open(path: Path, flags: int) -> int:
    """``os.open`` that refuses a symlink (one-line OutputError)."""
    try:
        return os.open(path, flags | _OPEN_FLAGS, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputError(f"{path} is a symlink; a campaign's journal must be a regular file") from exc
        raise


def _record(line: bytes, expected: Expected | None) -> dict[str, Any] | None:
    """The record on ``line`` (None: a run not planned); ValueError says what is wrong."""
    try:
        rec = json.loads(line)
    except ValueError:
        raise ValueError("not a JSON record") from None
    if not isinstance(rec, dict) or not isinstance(rec.get("run_hash"), str):
        raise ValueError("no run_hash")
    metrics = rec.get("metrics")
    if not isinstance(metrics, dict):
        raise ValueError("no metrics")
    if expected is None:
        return rec
    index = expected.index.get(rec["run_hash"])
    if index is None:
        return None
    if rec.get("index") != index:
        raise ValueError(f"run {rec['run_hash'][:12]} has index {rec.get('index')!r}, planned {index}")
    if set(metrics) != set(expected.columns):
        odd = sorted(set(metrics) ^ set(expected.columns))
        raise ValueError(f"metrics missing or not ours: {', '.join(odd[:3])[:80]}")
    for key, v in metrics.items():
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ValueError(f"metrics[{key!r}] is not a number")
    return {"run_hash": rec["run_hash"], "index": index, "metrics": metrics}


def read_journal(path: Path, expected: Expected | None = None) -> dict[str, dict[str, Any]]:
    """The whole records in ``path`` by run hash (none when it does not exist); with
    ``expected`` only planned runs, each checked (see the module docstring)."""
    try:
        fd = _open(path, os.O_RDONLY)
    except FileNotFoundError:
        return {}
    except OSError as exc:
        raise OutputError(f"cannot read {path}: {exc.strerror or exc}") from exc
    out: dict[str, dict[str, Any]] = {}
    with open(fd, "rb") as fh:
        for n, line in enumerate(iter(lambda: fh.readline(MAX_RECORD_BYTES + 1), b""), 1):
            if not line.endswith(b"\n"):
                if len(line) <= MAX_RECORD_BYTES:
                    break  # the part after the last newline is no whole record
                reason = f"longer than {MAX_RECORD_BYTES} bytes"
            else:
                try:
                    rec = _record(line, expected)
                except ValueError as exc:
                    reason = str(exc)
                else:
                    if rec is not None:
                        out[rec["run_hash"]] = rec
                    continue
            raise OutputError(
                f"{path} line {n}: {reason}; no record of this campaign (delete the line: "
                "--resume runs that run again)"
            )
    return out


class Journal:
    """The journal file of a campaign directory, open for appending (locked while open)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self._fd = _open(path, os.O_RDWR | os.O_CREAT | os.O_APPEND)
        except OutputError:
            raise
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
        """Sync to disk, unlock and close; a journal still empty (no run finished) is removed,
        so a campaign that never ran one leaves no journal to ``--resume``."""
        try:
            if os.fstat(self._fd).st_size == 0:
                self.path.unlink(missing_ok=True)  # still under our lock: no one appends to it
            else:
                os.fsync(self._fd)
        finally:
            os.close(self._fd)

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
