"""The optional installs (pyproject.toml's extras) and the check a command makes before it
needs one.

As python-can imports a backend only when it is asked for, the daemon and the emulator import
none of these; a command that needs one calls :func:`require` before importing it, so a missing
extra is one line naming the ``pip install`` to run (exit 2), never an ImportError traceback.
"""

from __future__ import annotations

import importlib.util

from .errors import MissingExtraError

#: extra name → the top-level modules it installs (pyproject.toml ``[project.optional-dependencies]``)
EXTRAS: dict[str, tuple[str, ...]] = {
    "campaign": ("dask", "distributed", "pyarrow", "scipy"),
    "fmu": ("fmpy",),
    "identify": ("scipy",),
    "mf4": ("asammdf",),
    "monitor": ("aiohttp",),
    "plot": ("matplotlib",),
}


def missing(modules: tuple[str, ...]) -> list[str]:
    """The names in ``modules`` that cannot be imported here (found without importing them)."""
    return [m for m in modules if importlib.util.find_spec(m) is None]


def require(extra: str, what: str, modules: tuple[str, ...] = ()) -> None:
    """Raise :class:`MissingExtraError` naming ``pip install 'ehpss-hil[extra]'`` when one of
    ``modules`` (default: all of the extra's) is not installed; ``what`` names the feature."""
    gone = missing(modules or EXTRAS[extra])
    if gone:
        raise MissingExtraError(
            f"{what} needs the optional '{extra}' install (missing: {', '.join(gone)}): "
            f"pip install 'ehpss-hil[{extra}]'"
        )
