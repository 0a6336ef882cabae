"""``ehpss-hil bench KIND``: benchmarks that print figures (never timed unit tests).

Each benchmark is a module in ``ehpss_hil/bench/`` defining ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``; they are discovered here.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from types import ModuleType

from .. import bench as bench_pkg

NAME = "bench"


def discover(package: ModuleType) -> list[ModuleType]:
    """The modules of ``package`` that define ``NAME`` and ``run`` (one per benchmark)."""
    mods = []
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{package.__name__}.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return mods


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="bench", metavar="KIND", required=True)
    for mod in discover(bench_pkg):
        sp = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(sp)
        sp.set_defaults(_bench_run=mod.run)


def run(args: argparse.Namespace) -> int:
    return int(args._bench_run(args) or 0)
