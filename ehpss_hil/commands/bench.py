"""``ehpss-hil bench KIND``: benchmarks that print figures (never timed unit tests).

Each benchmark is a module in ``ehpss_hil/bench/`` defining ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> Scorecard`` (every PASS/FAIL it printed,
:class:`ehpss_hil.bench.common.Scorecard`); :data:`~ehpss_hil.bench.BENCHES` names them. After
the bench, one line says how many targets passed and which failed; the exit code is 1 when any
failed, else 0.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from types import ModuleType

from .. import bench as bench_pkg
from ..bench import BENCHES
from ..bench.common import Scorecard

NAME = "bench"


def discover(package: ModuleType) -> list[ModuleType]:
    """The modules of ``package`` that define ``NAME`` and ``run`` (one per benchmark): what
    :data:`~ehpss_hil.bench.BENCHES` must list (tests/test_cli_help.py)."""
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
    for name in BENCHES:
        mod = importlib.import_module(f"{bench_pkg.__name__}.{name}")
        sp = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(sp)
        sp.set_defaults(_bench_run=mod.run)


def run(args: argparse.Namespace) -> int:
    card: Scorecard = args._bench_run(args)
    print(card.line(args.bench))
    return card.exit_code()
