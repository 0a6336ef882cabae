"""python-can's ``can.io.mf4`` loaded without asammdf until an MF4 log is asked for.

``can.io.mf4`` imports asammdf as soon as ``can`` is imported, and asammdf imports pandas (and
pandas pyarrow, where installed): with the ``mf4`` extra installed, every process — the daemon,
the emulator, each command — took 0.6 s instead of 0.09 s to import ``can`` here and carried
those packages. ``import ehpss_hil`` puts :class:`DeferAsammdf` on ``sys.meta_path``: it loads
``can.io.mf4`` (only that module) with asammdf hidden, so python-can takes it as missing.
:func:`ehpss_hil.canlog.binary.enable_mf4` calls :func:`release` and executes ``can.io.mf4``
again when an MF4 log is written or read. Nothing changes for a process that imported ``can``
or asammdf before ``ehpss_hil``; an ``import asammdf`` of anyone else is never affected.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from collections.abc import Sequence
from types import ModuleType

_MODULE = "can.io.mf4"


class _HidingLoader(importlib.abc.Loader):
    """Executes the real loader's module with ``sys.modules["asammdf"] = None`` (an import of
    asammdf raises ImportError meanwhile)."""

    def __init__(self, inner: importlib.abc.Loader) -> None:
        self._inner = inner

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._inner.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        if "asammdf" in sys.modules:  # imported meanwhile: nothing to hide
            self._inner.exec_module(module)
            return
        sys.modules["asammdf"] = None  # type: ignore[assignment]
        try:
            self._inner.exec_module(module)
        finally:
            if sys.modules.get("asammdf", 0) is None:
                del sys.modules["asammdf"]


class DeferAsammdf(importlib.abc.MetaPathFinder):
    """Finds ``can.io.mf4`` through the other finders and wraps its loader (until released)."""

    released = False

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname != _MODULE or DeferAsammdf.released or "asammdf" in sys.modules:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None and spec.loader is not None:
                spec.loader = _HidingLoader(spec.loader)
                return spec
        return None


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once; not when ``can`` is imported already)."""
    if "can" in sys.modules or any(isinstance(f, DeferAsammdf) for f in sys.meta_path):
        return
    sys.meta_path.insert(0, DeferAsammdf())


def release() -> None:
    """From now on ``can.io.mf4`` is found and executed as usual (with asammdf)."""
    DeferAsammdf.released = True
