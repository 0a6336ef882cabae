"""``ehpss-hil bench campaign``: campaign throughput on 1 and 2 local processes and on a Dask
``LocalCluster`` (2 worker processes on 127.0.0.1, as ``campaign --scheduler local:2``), the
per-run overhead beside the simulation time, and the offline speed of mmac; each target printed
with PASS/FAIL.

Overhead of an executor = (workers × wall time − Σ the runs' own time in the workers) / Σ the
runs' own time: what scheduling, transfer and idling add to the simulation.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from .. import PROJECT_ROOT
from ..campaign.localpool import run_local
from ..campaign.runs import RunTask, execute
from ..campaign.spec import load_campaign
from ..campaign.workers import Tally
from ..extras import EXTRAS, require
from .common import Scorecard, write_json
from .control import SPEED_TARGET

NAME = "campaign"
HELP = "campaign runs/s on 1 and 2 local processes and a local Dask cluster; overhead; mmac speed"

#: 2 workers against 1: at least this speed-up (2 cores)
SPEEDUP_TARGET = 1.8
#: Dask's overhead beside the simulation time, for runs of BENCH_DURATION_S
DASK_OVERHEAD_TARGET = 0.10
#: simulated duration of every benchmark run (s)
BENCH_DURATION_S = 4.0
WORKERS = 2


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--file", default=str(PROJECT_ROOT / "campaigns" / "quick.yaml"), help="campaign file")
    p.add_argument("--runs", type=int, default=16, help="runs per executor (default 16)")
    p.add_argument("--no-dask", action="store_true", help="skip the Dask LocalCluster")
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


def _timed(run: Callable[[Callable[[dict[str, Any]], None]], None]) -> tuple[float, list[dict[str, Any]]]:
    recs: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    run(recs.append)
    return time.perf_counter() - t0, recs


def _figures(name: str, wall: float, recs: list[dict[str, Any]], workers: int) -> dict[str, Any]:
    own = sum(r["timing"]["wall_s"] for r in recs)
    return {
        "executor": name,
        "runs": len(recs),
        "wall_s": wall,
        "runs_per_s": len(recs) / wall,
        "run_s": own / len(recs),
        "overhead": (workers * wall - own) / own,
    }


def _row(card: Scorecard, what: str, value: str, target: str, ok: bool | None) -> str:
    verdict = card.mark(ok, f"{what} {value} (target {target})")
    return f"{what:44s} {value:>14s}  {target:>16s}  {verdict}"


def run(args: argparse.Namespace) -> Scorecard:
    require("campaign", "ehpss-hil bench campaign", ("scipy",) if args.no_dask else EXTRAS["campaign"])
    from ..campaign.sampling import plan_runs

    card = Scorecard()
    camp = load_campaign(args.file)
    camp = replace(camp, spec=replace(camp.spec, duration_s=BENCH_DURATION_S))
    plans = plan_runs(camp)[: args.runs + 2]
    tasks = [
        RunTask(p.index, p.run_hash, p.scenario, camp.spec.modes, camp.spec.transport, camp.spec.tuning)
        for p in plans
    ]
    warm, tasks = tasks[:2], tasks[2:]
    for t in warm:  # imports, the DBC and the parameters loaded before timing (forked workers inherit)
        execute(t)
    results = []
    wall, recs = _timed(lambda cb: run_local(tasks, 1, cb))
    results.append(_figures("local ×1", wall, recs, 1))
    speeds = [r["timing"]["sim_s"] / r["timing"]["cpu_s"]["mmac"] for r in recs]
    wall, recs = _timed(lambda cb: run_local(tasks, WORKERS, cb))
    results.append(_figures(f"local ×{WORKERS}", wall, recs, WORKERS))
    if not args.no_dask:
        from ..campaign.cluster import LOCAL, DaskExecutor

        with DaskExecutor(f"{LOCAL}:{WORKERS}") as dask:
            dask.run(warm, lambda _r: None, Tally())  # the workers import and load once
            wall, recs = _timed(lambda cb: dask.run(tasks, cb, Tally()))
        results.append(_figures(f"Dask ×{WORKERS}", wall, recs, WORKERS))
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg())
    print(
        f"{len(tasks)} runs of {BENCH_DURATION_S:g} s × {len(camp.spec.modes)} modes per executor; "
        f"{os.cpu_count()} CPUs, load average {load} (other programs slow every figure)"
    )
    print(_row(card, "", "measured", "target", None))
    for r in results:
        print(_row(card, f"{r['executor']}: runs/s", f"{r['runs_per_s']:.2f}", "", None))
        print(_row(card, f"{r['executor']}: one run in its worker (s)", f"{r['run_s']:.3f}", "", None))
        dask = r["executor"].startswith("Dask")
        target = f"≤ {DASK_OVERHEAD_TARGET:.0%}" if dask else ""
        ok = r["overhead"] <= DASK_OVERHEAD_TARGET if dask else None
        print(_row(card, f"{r['executor']}: overhead", f"{r['overhead']:.1%}", target, ok))
    speedup = results[1]["runs_per_s"] / results[0]["runs_per_s"]
    print(
        _row(
            card,
            f"speed-up local ×{WORKERS} / ×1",
            f"{speedup:.2f}×",
            f"≥ {SPEEDUP_TARGET}×",
            speedup >= SPEEDUP_TARGET,
        )
    )
    if len(results) > 2:
        ratio = results[2]["runs_per_s"] / results[0]["runs_per_s"]
        print(_row(card, f"speed-up Dask ×{WORKERS} / local ×1", f"{ratio:.2f}×", "", None))
    worst, med = min(speeds), statistics.median(speeds)
    print(
        _row(
            card,
            "mmac offline speed, median run (× real time)",
            f"{med:.0f}×",
            f"≥ {SPEED_TARGET:.0f}×",
            med >= SPEED_TARGET,
        )
    )
    print(_row(card, "mmac offline speed, slowest run (× real time)", f"{worst:.0f}×", "", None))
    write_json(
        args.json, {"executors": results, "speedup": speedup, "mmac_speed": {"min": worst, "median": med}}
    )
    return card
