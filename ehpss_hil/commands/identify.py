"""``ehpss-hil identify (--scenario S.yaml | -c controller.yaml) --out P.yaml``: identify the
plant (in lockstep against a scenario's emulated plant, or on a live bus), write a params file."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from ..extras import require

NAME = "identify"


def add_arguments(p: argparse.ArgumentParser) -> None:
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--scenario",
        metavar="S.yaml",
        help="run the experiment in lockstep against the emulated plant of S's plant: section and "
        "noise (its reference and fault events are not used)",
    )
    where.add_argument(
        "-c",
        "--config",
        metavar="CONTROLLER.yaml",
        help="run it on the live bus of this controller config (the emulator or a real valve, any "
        "protocol profile) with the daemon's loop; the config's params are the start params",
    )
    p.add_argument(
        "--lockstep",
        action="store_true",
        help="with -c: one loop cycle per received sensor pair (the emulator in lockstep too)",
    )
    p.add_argument(
        "--rt-priority",
        type=int,
        metavar="N",
        help="with -c: SCHED_FIFO priority 1..99 for the loop (0 = none; overrides rt.priority)",
    )
    p.add_argument(
        "--cpu", type=int, metavar="N", help="with -c: pin the loop to this CPU (overrides rt.cpu)"
    )
    p.add_argument("--out", metavar="P.yaml", required=True, help="the params file to write")
    p.add_argument("--report", metavar="DIR", help="write report.md, frf.csv (and frf.png) here")
    p.add_argument(
        "--params",
        metavar="PARAMS.yaml",
        default="",
        help="with --scenario: the start params: PI gains of the experiment, the fit's start "
        "values and the keys not fitted (default configs/params.yaml)",
    )
    p.add_argument("--amplitude", type=float, metavar="M", help="peak of the multisine reference (m)")
    p.add_argument("--travel-limit", type=float, metavar="M", help="measured travel limit (m)")
    p.add_argument("--current-limit", type=float, metavar="A", help="commanded current limit (A)")


def run(args: argparse.Namespace) -> int:
    require("identify", "identify")
    from ..identify.engine import run_lockstep
    from ..identify.excitation import Excitation
    from ..identify.report import format_table
    from ..schema import build

    given = {
        "amplitude_m": args.amplitude,
        "travel_limit_m": args.travel_limit,
        "current_limit_a": args.current_limit,
    }
    exc = build(Excitation, {k: v for k, v in given.items() if v is not None}, "command line")
    report = Path(args.report) if args.report else None
    if args.config:
        from ..identify.engine import run_on_bus

        logging.basicConfig(
            level=logging.INFO, stream=sys.stderr, format="ehpss-hil identify: %(levelname)s: %(message)s"
        )
        ident = run_on_bus(
            Path(args.config), Path(args.out), report, exc, args.lockstep, args.rt_priority, args.cpu
        )
    else:
        ident = run_lockstep(args.scenario, Path(args.out), report, args.params, exc)
    print(format_table(ident.result, ident.truth))
    print(f"wrote {args.out}" + (f" and {args.report}/report.md" if args.report else ""))
    return 0
