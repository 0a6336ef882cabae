"""The run directory of ``ehpss-hil run``: a run only ever removes files a run wrote.

A run records every file it writes (relative paths) in the manifest
:data:`~ehpss_hil.outputs.MANIFEST` inside the directory (:mod:`ehpss_hil.outputs`, the one
proof of ownership every writer uses). Before a run:

- a missing or empty directory is used (and made);
- a directory with a manifest (or the ``run.json`` of a run older than manifests) is a run
  directory: the files listed there are removed (start-up waits read the new logs), anything
  else in it is left alone;
- any other non-empty directory is refused (:class:`~ehpss_hil.errors.OutputError`, exit 2)
  unless ``overwrite``: then only the files a run writes, by exact name (:func:`run_file_names`,
  plus the logs' numbered rotations), are removed.

A directory that cannot be written (read-only, full) is an :class:`OutputError` too, and leaves
no empty file behind.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path

from .errors import OutputError
from .outputs import MANIFEST, manifest_files, write_manifest

#: the tool named in the manifest of a run directory
TOOL = "ehpss-hil run"
#: the candump logs of a run (each with ``<log>.json`` and rotations ``<log>.N``)
RUN_LOGS = ("bus.log", "controller.log", "emulator.log")
#: the other files every run writes, by exact name
RUN_FILES = (
    "controller.yaml",
    "emulator.yaml",
    "logger.out",
    "controller.out",
    "emulator.out",
    "controller-summary.json",
    "emulator-summary.json",
    "run.json",
    "metrics.json",
)


def run_file_names() -> list[str]:
    """The fixed names of the files a run writes (rotations not included)."""
    out = list(RUN_FILES)
    for log in RUN_LOGS:
        out += [log, f"{log}.json", f"{log}.json.tmp"]
    return out


def _is_rotation(name: str) -> bool:
    return any(name.startswith(log + ".") and name[len(log) + 1 :].isdigit() for log in RUN_LOGS)


def read_manifest(out: Path) -> list[str] | None:
    """The files a run recorded in ``out`` (relative paths), or None when ``out`` is no run
    directory. A ``run.json`` of ``ehpss-hil run`` without a manifest stands for the fixed
    names."""
    files = manifest_files(out, TOOL)
    if files is not None:
        return files
    try:
        legacy = json.loads((out / "run.json").read_text())
    except (OSError, ValueError):
        return None
    if isinstance(legacy, dict) and legacy.get("tool") == TOOL:
        return run_file_names()
    return None


def _write_manifest(out: Path, files: Iterable[str]) -> None:
    write_manifest(out, TOOL, files)


def _remove(out: Path, names: Iterable[str]) -> None:
    """Unlink each relative path (a symlink itself, not its target); then the directories that
    became empty. Nothing outside ``out``, never a directory's contents."""
    root = out.resolve()
    dirs: set[Path] = set()
    for name in names:
        rel = Path(os.path.normpath(name))
        if rel.is_absolute() or ".." in rel.parts:
            continue
        p = root / rel
        if not (p.is_symlink() or p.is_file()):
            continue
        p.unlink()
        dirs.update(d for d in p.parents if root in d.parents)
    for d in sorted(dirs, key=lambda d: len(d.parts), reverse=True):
        try:
            d.rmdir()  # only when it became empty
        except OSError:
            pass


def prepare_run_dir(out: Path, overwrite: bool = False) -> None:
    """Make ``out`` ready for a run (see the module docstring); raises :class:`OutputError`
    (and then removes ``out`` again when it made it)."""
    made = not out.exists()
    try:
        if out.exists() and not out.is_dir():
            raise OutputError(f"{out}: exists and is not a directory")
        out.mkdir(parents=True, exist_ok=True)
        present = sorted(p.name for p in out.iterdir())
        listed = read_manifest(out)
        if listed is None and present and not overwrite:
            shown = ", ".join(present[:4]) + (", …" if len(present) > 4 else "")
            raise OutputError(
                f"{out}: not empty and not a run directory ({shown}); choose a new or empty "
                "--out, or add --overwrite (replaces only the files a run writes)"
            )
        if listed is None:
            listed = [n for n in present if n in run_file_names()]
        # the logs' rotations: a run's loggers remove them anyway when they open their logs
        _remove(out, [*listed, *(n for n in present if _is_rotation(n))])
        _write_manifest(out, run_file_names())
    except OSError as exc:
        if made:
            try:
                out.rmdir()
            except OSError:
                pass
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"{out}: cannot prepare the run directory: {exc.strerror or exc}") from exc


def record_outputs(out: Path, paths: Iterable[Path] = ()) -> None:
    """Add the files written so far to the manifest: the fixed names, the logs' rotations and
    ``paths`` (e.g. report figures). Raises :class:`OutputError` when it cannot be written."""
    names = set(read_manifest(out) or []) | set(run_file_names())
    names |= {p.name for p in out.iterdir() if _is_rotation(p.name)}
    names |= {os.path.relpath(p, out) for p in paths}
    try:
        _write_manifest(out, names)
    except OSError as exc:
        raise OutputError(f"{out / MANIFEST}: cannot write: {exc.strerror or exc}") from exc
