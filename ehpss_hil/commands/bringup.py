"""``ehpss-hil bringup -c controller.yaml``: the checks before the first enable — bit rate,
the node's identity (CiA 408), sensor zero and spool null, the echo's, the spool's and the
piston's polarity under a small bounded current (docs/hardware.md §4.1). Exit 0 when every check
passes; a failed one is one line naming it (exit 3; 2 for a bad config or bit rate)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

NAME = "bringup"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-c", "--config", required=True, type=Path, help="the controller config (bus, profile)")
    p.add_argument(
        "--lockstep",
        action="store_true",
        help="one loop cycle per received sensor pair (the emulator in lockstep too)",
    )
    p.add_argument(
        "--current-share", type=float, metavar="X", help="test current / the spool's stroke current (0.1)"
    )
    p.add_argument("--step", type=float, metavar="S", help="seconds at +I and at −I (0.2)")
    p.add_argument("--travel-limit", type=float, metavar="M", help="piston travel limit from rest (m, 0.002)")


def run(args: argparse.Namespace) -> int:
    from ..bringup.engine import require_ok, run_bringup
    from ..bringup.sequence import BringupPlan
    from ..schema import build

    logging.basicConfig(
        level=logging.INFO, stream=sys.stderr, format="ehpss-hil bringup: %(levelname)s: %(message)s"
    )
    given = {"current_share": args.current_share, "step_s": args.step, "travel_limit_m": args.travel_limit}
    plan = build(BringupPlan, {k: v for k, v in given.items() if v is not None}, "command line")
    result = run_bringup(args.config, plan, args.lockstep)
    print(result.bitrate)
    for f in result.findings:
        print(f"{f.name:9s} {'PASS' if f.ok else 'FAIL'}  {f.text}")
    require_ok(result)
    print("bring-up: every check passed; the valve may be enabled")
    return 0
