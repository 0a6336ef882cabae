"""``ehpss-hil replay LOG [--mode M]``: the arguments, and the verdict printed; the replay itself
is :func:`ehpss_hil.replay.engine.replay_log` (docs/logs.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..replay.engine import Divergence, replay_log

NAME = "replay"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``ehpss-hil replay``."""
    p.add_argument(
        "log", type=Path, help="a log python-can reads (candump -L .log, .asc, .blf, …) or its directory"
    )
    p.add_argument("--mode", default=None, help="controller mode (default: the logged one)")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="controller.yaml the run used (reference, tuning, params, rate)",
    )
    p.add_argument(
        "--scenario", type=Path, default=None, help="scenario YAML for the reference and sample time"
    )
    p.add_argument("--show", type=int, default=5, help="divergences to print (default 5)")
    p.add_argument(
        "--gaps",
        choices=("auto", "overrun", "lost"),
        default="auto",
        help="CycleCount gaps are periods the daemon slept through (overrun) or "
        "commands lost on the bus (lost); auto: lost for a lockstep log (its "
        "sidecar says so), else overrun",
    )


def describe(d: Divergence, ts_s: float) -> str:
    """One line for a divergence."""
    lsb = 2e-7
    return (
        f"cycle {d.cycle} (t = {d.cycle * ts_s:.4f} s, frame #{d.frame_number} of the log): "
        f"logged {d.logged_a:+.7f} A (enable {int(d.logged_enable)}), replayed "
        f"{d.replayed_a:+.7f} A (enable {int(d.replayed_enable)}), "
        f"diff {(d.replayed_a - d.logged_a) / lsb:+.0f} LSB"
    )


def run(args: argparse.Namespace) -> int:
    """Replay and print the verdict: 0 identical, 1 diverged."""
    res = replay_log(args.log, args.mode, args.config, args.scenario, args.show, args.gaps)
    s = res.setup
    print(
        f"replayed {res.cycles} cycles with mode {s.mode} at Ts = {s.ts_s * 1e3:g} ms "
        f"(config from {s.source})"
    )
    if res.bad_lines.count:
        print(f"{res.bad_lines.text()} (not frame lines: a cut last line or garbage)")
    if res.clock_steps_back:
        print(
            f"note: the log's clock went back {res.clock_steps_back} time(s) by more than its "
            "reorder window: the frames before each step are replayed first (file order)"
        )
    if res.skipped_periods:
        print(
            f"{res.skipped_periods} periods skipped by the daemon's overruns (CycleCount gaps) "
            "stepped without a frame, as the daemon does"
        )
    if res.failsafe_cycles:
        print(
            f"{res.failsafe_cycles} fail-safe cycles (logged Enable=0) skipped; the controller "
            "is reset when they end, as the daemon does"
        )
    if res.identical:
        print("identical: every replayed VALVE_CMD equals the logged one bit for bit")
        return 0
    print(
        f"DIVERGED in {res.divergent} of {res.cycles} cycles (max |diff| "
        f"{res.max_abs_diff_a:.3g} A); first divergence:"
    )
    for d in res.first:
        print("  " + describe(d, s.ts_s))
    return 1
