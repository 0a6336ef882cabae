"""The per-sample code compiled to C with mypyc, and the guard that keeps a stale build out.

The controller (:mod:`ehpss_hil.control`: every module but :data:`SOURCE_ONLY`) and the
nonlinear plant (:mod:`ehpss_hil.physics.hydraulics`) run once per sample, thousands of times
per simulated second. :mod:`.nativebuild` compiles exactly these sources, unchanged, with mypyc
(shipped with mypy, in the dev lock) into C extensions beside them; ``make`` runs it when it
sets up ``.venv``. Python then imports the extension instead of the source: the same
arithmetic in the same order (double precision both ways), 2–5× faster (``ehpss-hil bench
control`` prints the speed and whether it ran compiled).

The build writes a manifest (:data:`MANIFEST`: each source's size, mtime and SHA-256). A source
changed since the build (an edit, a checkout) would be shadowed by its old extension, so
importing :mod:`ehpss_hil` checks the manifest first (:func:`guard`) and, if any compiled
source changed, an extension the build made is missing or one lies about that it did not make,
imports every compiled module from its source (the whole group: compiled modules call each
other's classes natively, so a mix of old and new would run two versions of a class), with
one line on stderr that says so. Without a build (no mypy, no C compiler: the base lock of a
bench PC) everything runs from source, as it always can.

Only the standard library is imported here: this runs before anything else in the package.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

#: the package directory (ehpss_hil/)
PACKAGE_DIR = Path(__file__).resolve().parent
#: the manifest of the build, beside the package's sources
MANIFEST = PACKAGE_DIR / "_native.json"
#: mypyc's group of the compiled modules
GROUP = "ehpss_hil._native"
#: the group's shared library, a module beside the package's (mypyc names it after the group)
SHARED_LIB = GROUP + "__mypyc"
#: what is compiled: packages (every module below them) and modules, by dotted name
COMPILED: tuple[str, ...] = ("ehpss_hil.control", "ehpss_hil.physics.hydraulics")
#: modules below :data:`COMPILED` that stay source, read once per controller, not per sample:
#: the tuning (a compiled frozen dataclass could not be unpickled on a campaign's workers, nor
#: read by the config schema through its annotations) and the controller contract (the ABC
#: every custom law subclasses: compiled, a subclass's ``mode`` and a missing abstract method
#: would go unseen)
SOURCE_ONLY: frozenset[str] = frozenset({"ehpss_hil.control.base", "ehpss_hil.control.tuning"})

_EXT_SUFFIXES = tuple(importlib.machinery.EXTENSION_SUFFIXES)


def source(name: str) -> Path:
    """The source file of module or package ``name`` (ehpss_hil.…; a package: its ``__init__.py``)."""
    rel = Path(*name.split(".")[1:])
    pkg = PACKAGE_DIR / rel
    return pkg / "__init__.py" if pkg.is_dir() else pkg.with_suffix(".py")


def candidates() -> set[str]:
    """Every module :data:`COMPILED` names or holds, :data:`SOURCE_ONLY` included."""
    out: set[str] = set()
    for name in COMPILED:
        src = source(name)
        if src.name != "__init__.py":
            out.add(name)
            continue
        for py in src.parent.rglob("*.py"):
            if py.name != "__init__.py":
                out.add(".".join(("ehpss_hil", *py.relative_to(PACKAGE_DIR).with_suffix("").parts)))
    return out


def modules() -> list[str]:
    """Every module compiled, by dotted name, sorted: the modules below the packages of
    :data:`COMPILED` and the plain modules named there, less :data:`SOURCE_ONLY`. A package's
    ``__init__`` stays source (mypyc gives a compiled package in a named group a wrong
    ``__path__``)."""
    return sorted(candidates() - SOURCE_ONLY)


def extension(name: str) -> Path | None:
    """The compiled extension of module ``name`` beside its source, if there is one."""
    src = source(name)
    for suffix in _EXT_SUFFIXES:
        ext = src.with_name(src.stem + suffix)
        if ext.exists():
            return ext
    return None


def on_disk() -> dict[str, Path]:
    """Every extension module under the package by dotted name (the group's shared library
    aside): what a build left, whether or not it is in the build now."""
    out: dict[str, Path] = {}
    for root, dirs, files in os.walk(PACKAGE_DIR):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for f in files:
            suffix = next((x for x in _EXT_SUFFIXES if f.endswith(x)), None)
            if suffix is None:
                continue
            parts = Path(root, f[: -len(suffix)]).relative_to(PACKAGE_DIR).parts
            name = ".".join(("ehpss_hil", *parts))
            if name != SHARED_LIB:
                out[name] = Path(root, f)
    return out


def _digest(path: Path) -> str:
    """SHA-256 of the file (hashlib loads OpenSSL: only when a size or mtime differs)."""
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def record(path: Path) -> dict[str, object]:
    """What the manifest keeps of a compiled source: size, mtime (ns) and SHA-256."""
    st = path.stat()
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns, "sha256": _digest(path)}


def stale() -> list[str]:
    """The extension modules that must not be imported as built: their source changed since
    the build, one the build made is missing, an extension lies about that the manifest does
    not list (a module that left the build, one that is to stay source), or extensions without
    a manifest. Empty when nothing is compiled, or the build matches the sources."""
    found = on_disk()
    try:
        data = json.loads(MANIFEST.read_text(encoding="utf-8"))
        recs: dict[str, dict[str, object]] = data["modules"]
    except FileNotFoundError:
        return sorted(found)
    except (OSError, ValueError, KeyError, TypeError):
        return sorted(set(found) | set(modules()))
    out = sorted(set(found) - set(recs))
    for name in modules():
        rec = recs.get(name)
        if rec is None or name not in found:
            out.append(name)
            continue
        src = source(name)
        st = src.stat()
        if st.st_size == rec.get("size") and st.st_mtime_ns == rec.get("mtime_ns"):
            continue
        if _digest(src) != rec.get("sha256"):
            out.append(name)
    return out


def compiled() -> bool:
    """The compiled modules are the ones imported (built, and the build matches the sources)."""
    return MANIFEST.exists() and not stale() and not any(isinstance(f, _SourceFirst) for f in sys.meta_path)


class _SourceFirst(importlib.abc.MetaPathFinder):
    """Imports the named modules from their ``.py`` sources, past their extensions."""

    def __init__(self, names: Sequence[str]) -> None:
        self._names = frozenset(names)

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname not in self._names:
            return None
        return importlib.util.spec_from_file_location(fullname, source(fullname))


def guard() -> None:
    """Run once when :mod:`ehpss_hil` is imported: if the build does not match the sources,
    every compiled module is imported from source from now on, and stderr says so once."""
    if any(isinstance(f, _SourceFirst) for f in sys.meta_path):
        return
    changed = stale()
    if not changed:
        return
    sys.meta_path.insert(0, _SourceFirst(sorted(candidates() | set(on_disk()))))
    sys.stderr.write(
        f"ehpss-hil: {len(changed)} compiled module(s) do not match their source "
        f"(e.g. {changed[0]}): running every compiled module from source; "
        "`make native` rebuilds them\n"
    )


def status() -> str:
    """One line: compiled, stale (running from source) or not built."""
    if not MANIFEST.exists():
        return "not built: every module runs from source"
    changed = stale()
    if changed:
        return f"stale: {len(changed)} compiled module(s) do not match their source; running from source"
    return f"compiled: {len(modules())} modules"
