"""``ehpss-hil campaign FILE``: a Monte-Carlo fault campaign on local processes or a Dask cluster
(docs/campaigns.md). Ctrl-C stops it, keeps every finished run and exits 130; ``--resume`` goes on."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..campaign.executors import default_workers
from ..campaign.spec import load_campaign
from ..extras import EXTRAS, require

NAME = "campaign"
#: exit code after Ctrl-C (the shell's 128 + SIGINT)
INTERRUPTED_EXIT = 130


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
        "--scheduler", metavar="ADDRESS", help="run on the Dask cluster of this scheduler (tcp://host:8786)"
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


def run(args: argparse.Namespace) -> int:
    require("campaign", "ehpss-hil campaign", EXTRAS["campaign"] if args.scheduler else LOCAL_MODULES)
    from ..campaign.session import run_campaign
    from ..campaign.summary import format_summary

    camp = load_campaign(args.file)
    out = Path(args.out) if args.out else Path("runs") / f"campaign-{camp.spec.name}"
    where = (
        f"Dask scheduler {args.scheduler}" if args.scheduler else f"{max(1, args.workers)} local process(es)"
    )
    spec = camp.spec
    print(f"campaign {spec.name}: {spec.samples} runs × {len(spec.modes)} modes on {where} → {out}")
    t0 = time.perf_counter()
    try:
        res = run_campaign(
            camp,
            out,
            max(1, args.workers),
            args.scheduler,
            args.resume,
            args.csv,
            not args.no_figures,
            overwrite=args.overwrite,
        )
    except KeyboardInterrupt:
        print(f"\ninterrupted: the finished runs are kept in {out}; continue with --resume", file=sys.stderr)
        return INTERRUPTED_EXIT
    wall = time.perf_counter() - t0
    print(format_summary(res.summaries))
    rate = f" ({res.ran / res.run_wall_s:.2f} runs/s)" if res.ran and res.run_wall_s > 0 else ""
    print(f"{res.ran} run(s) done{rate}, {res.skipped} skipped (finished before); {wall:.1f} s in all")
    for f in res.files:
        print(f"wrote {f}")
    return 0
