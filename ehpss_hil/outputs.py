"""Whose file is it: a writer replaces or deletes only the files it can prove it wrote.

The proof is a record the writer leaves beside its files and keeps current:

- a directory's manifest :data:`MANIFEST` (``{"tool": …, "files": [relative paths]}``), written
  by ``ehpss-hil run`` (:mod:`ehpss_hil.rundir`) and ``ehpss-hil campaign``
  (:mod:`ehpss_hil.campaign.session`): a tool trusts only a manifest that names it;
- a candump log's sidecar ``<log>.json`` (:mod:`ehpss_hil.canlog.sidecar`), naming the log and
  every file of its rotation set.

A target that exists without that proof is foreign: the writer refuses it with one line
(:func:`refuse_foreign`, an :class:`~ehpss_hil.errors.OutputError`, exit 2) unless the user
passed ``--overwrite``; even then it replaces only the names it writes, never other files. A
record is read only from a regular file (not a symlink) of at most :data:`MAX_RECORD_BYTES`.
"""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Collection, Iterable
from pathlib import Path
from typing import Any

from .errors import OutputError

#: the manifest of a directory an ehpss-hil tool writes into
MANIFEST = ".ehpss-run.json"
#: a manifest or sidecar larger than this (bytes) is no record of ours (ours are a few kB)
MAX_RECORD_BYTES = 1 << 20
#: foreign files named in a refusal before "…"
_SHOWN = 4


def read_record(path: Path) -> dict[str, Any] | None:
    """The JSON object in ``path``, or None when it is missing, a symlink, not a regular file,
    larger than :data:`MAX_RECORD_BYTES` or not a JSON object."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_RECORD_BYTES:
            return None
        raw = os.read(fd, MAX_RECORD_BYTES + 1)
    except OSError:
        return None
    finally:
        os.close(fd)
    try:
        data = json.loads(raw)
    except ValueError:
        return None
    return data if isinstance(data, dict) else None


def manifest_files(out: Path, tool: str) -> list[str] | None:
    """The relative paths ``tool`` recorded in ``out``'s manifest (None: no manifest of it)."""
    data = read_record(out / MANIFEST)
    if data is None or data.get("tool") != tool or not isinstance(data.get("files"), list):
        return None
    return [f for f in data["files"] if isinstance(f, str)]


def write_manifest(out: Path, tool: str, files: Iterable[str]) -> None:
    """Record ``files`` (relative paths) as written by ``tool`` in ``out`` (atomically: a
    temporary file, then ``os.replace``; a failed write leaves no temporary file and raises
    OSError)."""
    raw = json.dumps({"tool": tool, "files": sorted(set(files))}, indent=2) + "\n"
    path = out / MANIFEST
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(raw)
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise


def exists(path: Path) -> bool:
    """``path`` exists (a dangling symlink counts: replacing it is replacing the user's link)."""
    return path.is_symlink() or path.exists()


def foreign(paths: Iterable[Path], ours: Collection[str], root: Path) -> list[Path]:
    """The paths that exist and are not recorded as ours (``ours``: paths relative to ``root``)."""
    return [p for p in paths if exists(p) and os.path.relpath(p, root) not in ours]


def refuse_foreign(target: Path, found: list[Path], what: str) -> None:
    """Raise the one-line :class:`OutputError` for ``found`` foreign files at ``target``; nothing
    when ``found`` is empty. ``what``: what the tool would write there (``a log``, …)."""
    if not found:
        return
    names = ", ".join(p.name for p in found[:_SHOWN]) + (", …" if len(found) > _SHOWN else "")
    raise OutputError(
        f"{target}: {names} exist(s) and ehpss-hil did not write them; {what} would replace "
        "them: choose another target, or add --overwrite (replaces only the files it writes)"
    )
