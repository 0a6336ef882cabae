"""The JSON sidecar ``<log>.json``: what produced a log and what it holds.

Keys: ``format`` (``candump -L``, ``BLF`` or ``MF4``), ``log``, ``iface``, ``versions``
(ehpss-hil, python-can, cantools, python), ``dbc`` (path, sha256), ``start_time_utc`` /
``start_time_s``, ``clock`` (what ``msg.timestamp`` is), ``rotation``, ``status``
(open/closed), ``counts`` (written, dropped, discarded_by_rotation, and when lines were dropped
``dropped_by_reason``: queue full, after close, disk full, write error),
``files`` (oldest first: name, lines, bytes, first/last timestamp), ``error``, plus every key the
caller passed (``config``, ``scenario``, ``process``, …). Whether the run was lockstep is in
``lockstep`` (the controller daemon, ``run.json``) or ``mode`` / ``config.mode`` (firmware-sim:
``lockstep`` or ``realtime``); :func:`lockstep_of` reads it.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import json
import os
import platform
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from .. import DEFAULT_DBC, __version__
from .candumpfile import numbered
from .formats import SIDECAR_FORMATS

DEFAULT_CLOCK = (
    "msg.timestamp as given by python-can: wall clock, seconds since the Unix epoch "
    "(time.time() for frames the process builds)"
)


@dataclass
class FileRecord:
    """Lines and byte count of one file of a rotation set, with its first/last timestamp (s)."""

    lines: int = 0
    bytes: int = 0
    first_t_s: float | None = None
    last_t_s: float | None = None

    def add(self, lines: int, nbytes: int, first_t_s: float, last_t_s: float) -> None:
        """Account a chunk of ``lines`` lines, ``nbytes`` bytes."""
        if self.first_t_s is None:
            self.first_t_s = first_t_s
        self.last_t_s = last_t_s
        self.lines += lines
        self.bytes += nbytes

    def as_dict(self, name: str) -> dict[str, Any]:
        """JSON form, with the file's current name."""
        return {
            "name": name,
            "lines": self.lines,
            "bytes": self.bytes,
            "first_t_s": self.first_t_s,
            "last_t_s": self.last_t_s,
        }


def sidecar_path(log_path: str | os.PathLike[str]) -> Path:
    """``run.log`` → ``run.log.json``."""
    p = Path(log_path)
    return p.with_name(p.name + ".json")


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def file_sha256(path: str | os.PathLike[str]) -> str | None:
    """Hex SHA-256 of a file, or None when it cannot be read."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


#: the emulator's ``mode`` values (its sidecar and config): how its clock ran
_TIMING_MODES = {"lockstep": True, "realtime": False}


def lockstep_of(side: dict[str, Any] | None) -> bool | None:
    """True when a sidecar (or ``run.json``) says its run was lockstep — the wall clock then
    does not follow the controller's cycles —, False when it says realtime, None when it does
    not say: ``lockstep`` (a bool: the controller daemon, ``ehpss-hil run``), else ``mode`` or
    ``config.mode`` when it is ``lockstep``/``realtime`` (firmware-sim)."""
    if not isinstance(side, dict):
        return None
    flag = side.get("lockstep")
    if isinstance(flag, bool):
        return flag
    cfg = side.get("config")
    for mode in (side.get("mode"), cfg.get("mode") if isinstance(cfg, dict) else None):
        if isinstance(mode, str) and mode in _TIMING_MODES:
            return _TIMING_MODES[mode]
    return None


def jsonable(obj: Any) -> Any:
    """Dataclasses, paths, tuples and sets made JSON-serializable (recursively)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return jsonable(dataclasses.asdict(obj))
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if obj is None or isinstance(obj, (str, int, float, bool)):
        return obj
    return str(obj)


def build_sidecar(
    log_path: Path, iface: str, caller: dict[str, Any] | None, max_bytes: int, backups: int, queue_lines: int
) -> dict[str, Any]:
    """The initial sidecar mapping (counts and files are filled in by the writer)."""
    meta: dict[str, Any] = jsonable(dict(caller or {}))
    dbc = meta.get("dbc")
    dbc_path = dbc.get("path") if isinstance(dbc, dict) else dbc
    dbc_path = str(dbc_path) if dbc_path else str(DEFAULT_DBC)
    clock = meta.get("clock")
    now = time.time()
    meta.update(
        {
            "format": "candump -L",
            "log": log_path.name,
            "iface": iface,
            "versions": {
                "ehpss-hil": __version__,
                "python-can": _version("python-can"),
                "cantools": _version("cantools"),
                "python": platform.python_version(),
            },
            "dbc": {"path": dbc_path, "sha256": file_sha256(dbc_path)},
            "start_time_s": now,
            "start_time_utc": dt.datetime.fromtimestamp(now, dt.UTC).isoformat(),
            "clock": clock if clock else DEFAULT_CLOCK,
            "rotation": {"max_bytes": max_bytes, "backups": backups, "queue_lines": queue_lines},
        }
    )
    return meta


#: room (bytes) a sidecar keeps for its own later updates (trailing spaces, valid JSON)
SIDECAR_RESERVE_BYTES = 4096


def write_json_atomic(path: Path, data: dict[str, Any], reserve_bytes: int = 0) -> None:
    """Write ``data`` to ``path`` via a temporary file and ``os.replace`` (never half a file).

    ``reserve_bytes`` > 0: the file is padded with trailing spaces to a whole number of 4 KiB
    blocks at least this much longer than the JSON, and when the temporary file cannot be
    written (a full disk) the JSON is written over the existing file inside the space it already
    holds (no new block needed). A failed write leaves no temporary file and raises OSError.
    """
    raw = (json.dumps(data, indent=2, sort_keys=False, default=str) + "\n").encode()
    if reserve_bytes > 0:
        size = -(-(len(raw) + reserve_bytes) // 4096) * 4096
        raw = raw[:-1] + b" " * (size - len(raw)) + b"\n"
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as fh:
            fh.write(raw)
        os.replace(tmp, path)
    except OSError:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        if reserve_bytes <= 0 or not _write_in_place(path, raw.rstrip() + b"\n"):
            raise


def _write_in_place(path: Path, raw: bytes) -> bool:
    """Overwrite ``path`` with ``raw`` padded to its current size; False when it does not fit."""
    try:
        size = path.stat().st_size
        if len(raw) > size:
            return False
        with open(path, "r+b") as fh:
            fh.write(raw[:-1] + b" " * (size - len(raw)) + b"\n")
    except OSError:
        return False
    return True


def owned_names(log_path: Path) -> set[str]:
    """The names (in the log's folder) of the files the sidecar ``<log>.json`` proves a
    :class:`~ehpss_hil.canlog.writer.CandumpLogger` wrote (in any of its formats): the log, the
    sidecar and the rotated files it lists (``<log>.N`` only, whatever else it says); empty
    without such a sidecar."""
    from ..outputs import read_record

    side = sidecar_path(log_path)
    data = read_record(side)
    if data is None or data.get("format") not in SIDECAR_FORMATS.values() or data.get("log") != log_path.name:
        return set()
    names = {log_path.name, side.name}
    files = data.get("files")
    for f in files if isinstance(files, list) else []:
        name = f.get("name") if isinstance(f, dict) else None
        if isinstance(name, str) and is_rotation_of(log_path.name, name):
            names.add(name)
    return names


def is_rotation_of(log_name: str, name: str) -> bool:
    """``name`` is a rotated file ``<log_name>.N`` (N a positive decimal number)."""
    tail = name[len(log_name) + 1 :] if name.startswith(log_name + ".") else ""
    return tail.isdecimal() and tail.isascii() and int(tail) > 0


def claim_log_names(path: Path, backups: int, what: str, overwrite: bool) -> None:
    """Before a log is opened at ``path``: refuse a foreign file among its names (the log, its
    sidecar, ``path.1`` … ``path.<backups>``; :class:`~ehpss_hil.errors.OutputError` naming
    ``what`` would be written) unless ``overwrite``; remove the earlier log's rotated files
    (those its sidecar lists, nothing else)."""
    from ..outputs import foreign, refuse_foreign

    root = path.parent
    ours = owned_names(path)
    rotated = (numbered(path, i) for i in range(1, backups + 1))
    names = [path, sidecar_path(path), *rotated]
    if not overwrite:
        refuse_foreign(path, foreign(names, ours, root), what)
    for name in sorted(ours):
        p = root / name
        if is_rotation_of(path.name, name) and (p.is_symlink() or p.is_file()):
            p.unlink()
