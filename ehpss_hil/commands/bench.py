"""``ehpss-hil bench KIND``: benchmarks that print figures (never timed unit tests).

Each benchmark is a module in ``ehpss_hil/bench/`` defining ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``; they are discovered here.
"""

from __future__ import annotations

import argparse

from .. import bench as bench_pkg
from ..cli import discover

NAME = "bench"
HELP = "benchmarks: codec, control, loop, faults, soak (print figures beside their targets)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="bench", metavar="KIND", required=True)
    for mod in discover(bench_pkg):
        sp = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(sp)
        sp.set_defaults(_bench_run=mod.run)


def run(args: argparse.Namespace) -> int:
    return int(args._bench_run(args) or 0)
