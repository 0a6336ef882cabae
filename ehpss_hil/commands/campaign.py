"""``ehpss-hil campaign FILE``: a Monte-Carlo fault campaign on local processes or a Dask cluster
(docs/campaigns.md). Ctrl-C stops it, keeps every finished run and exits 130; ``--resume`` goes on."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from ..campaign.spec import load_campaign
from ..campaign.workers import CONNECT_TIMEOUT_RANGE_S, CONNECT_TIMEOUT_S, default_workers
from ..errors import ConfigError, WorkerLostError
from ..extras import EXTRAS, require
from ..interrupt import INTERRUPTED_EXIT

if TYPE_CHECKING:
    from ..campaign.session import Outcome

NAME = "campaign"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="campaign YAML file (campaigns/*.yaml)")
    p.add_argument(
        "--workers",
        "-j",
        type=int,
        default=default_workers(),
        help="local worker processes (default: all cores; ignored with --scheduler)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on Dask: the cluster of this scheduler (tcp://host:8786), or local[:N] for a "
        "distributed.LocalCluster of N worker processes here (default N: all cores)",
    )
    p.add_argument(
        "--connect-timeout",
        type=float,
        default=CONNECT_TIMEOUT_S,
        metavar="S",
        help=f"with a scheduler address: how long it may take to answer, in seconds (default "
        f"{CONNECT_TIMEOUT_S:g}; a closed port is retried until then)",
    )
    p.add_argument(
        "--retries",
        type=int,
        default=0,
        metavar="N",
        help="submit a run that fails (or whose workers keep dying) again up to N times (default 0; "
        "a lost worker's runs run again anyway, local or on Dask)",
    )
    p.add_argument("--out", "-o", metavar="DIR", help="output directory (default: runs/campaign-<name>)")
    p.add_argument("--resume", action="store_true", help="continue in DIR: runs already finished are skipped")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace files at the campaign's names in DIR that it did not write (others are kept)",
    )
    p.add_argument("--csv", action="store_true", help="also write results.csv")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")


#: what a campaign imports from the ``campaign`` extra: Parquet tables and the QMC samplers;
#: Dask's client only for ``--scheduler``
LOCAL_MODULES = ("pyarrow", "scipy")


#: most retries of one run
MAX_RETRIES = 100


def run(args: argparse.Namespace) -> int:
    require("campaign", "ehpss-hil campaign", EXTRAS["campaign"] if args.scheduler else LOCAL_MODULES)
    if not 0 <= args.retries <= MAX_RETRIES:
        raise ConfigError("", "--retries", f"expected 0 … {MAX_RETRIES}, got {args.retries}")
    lo, hi = CONNECT_TIMEOUT_RANGE_S
    if not lo <= args.connect_timeout <= hi:  # also NaN
        raise ConfigError(
            "", "--connect-timeout", f"expected {lo:g} … {hi:g} s, got {args.connect_timeout:g}"
        )
    from ..campaign.executors import open_executor
    from ..campaign.session import run_campaign

    camp = load_campaign(args.file)
    out = Path(args.out) if args.out else Path("runs") / f"campaign-{camp.spec.name}"
    t0 = time.perf_counter()
    try:
        with open_executor(max(1, args.workers), args.scheduler, args.retries, args.connect_timeout) as ex:
            spec = camp.spec
            runs = f"{spec.samples} runs × {len(spec.modes)} modes"
            print(f"campaign {spec.name}: {runs} on {ex.description} → {out}")
            if args.scheduler:
                print(f"Dask dashboard: {ex.dashboard or 'none (the scheduler serves none)'}", flush=True)
            res = run_campaign(
                camp,
                out,
                resume=args.resume,
                csv=args.csv,
                figures=not args.no_figures,
                overwrite=args.overwrite,
                executor=ex,
            )
    except KeyboardInterrupt:
        print(f"\ninterrupted: the finished runs are kept in {out}; continue with --resume", file=sys.stderr)
        return INTERRUPTED_EXIT
    except WorkerLostError as exc:
        raise WorkerLostError(f"{exc}; the finished runs are kept in {out}: continue with --resume") from None
    _report(res, time.perf_counter() - t0)
    return 0


def _report(res: Outcome, wall: float) -> None:
    """The summary table, the counts and the files written, on stdout."""
    from ..campaign.summary import format_summary

    print(format_summary(res.summaries))
    rate = f" ({res.ran / res.run_wall_s:.2f} runs/s)" if res.ran and res.run_wall_s > 0 else ""
    trouble = res.tally.text()
    print(
        f"{res.ran} run(s) done{rate}, {res.skipped} skipped (finished before)"
        + (f", {trouble}" if trouble else "")
        + f"; {wall:.1f} s in all"
    )
    for f in res.files:
        print(f"wrote {f}")
