"""``ehpss-hil demo``: the README's main command.

Case 3 (sensor drift 0.8 at 1 s, then LOE 50 % at 2 s) with ``firmware-sim`` and the controller
as two real processes on the embedded bus (plus a bus logger), once with NRC and once with MMAC;
then the metrics side by side, next to the deterministic offline simulation of the same
scenario, and where the logs and figures are. Where this host can neither make a private
network namespace nor route multicast, it says so and shows the offline simulation only.

The result starts with the realtime verdict of the two-process runs
(:mod:`ehpss_hil.runtime.rtverdict`) and, when the host did not hold the rate, what to do about
it; exit 4 then (the figures shown are not the controller's), else 0.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from .. import PROJECT_ROOT
from ..errors import BusUnavailableError
from ..extras import require
from ..orchestrate import RunPlan, check_exit_codes, execute
from ..report.metrics import compute_metrics
from ..run_metrics import metrics_from_run
from ..runtime.rtverdict import REALTIME_INVALID_EXIT, RealtimeVerdict, combine, end_trip
from ..scenario import load_scenario
from ..sim.lockstep import run_scenario
from . import check_config

NAME = "demo"

MODES = ("nrc", "mmac")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output directory")
    p.add_argument("--scenario", type=Path, default=PROJECT_ROOT / "scenarios" / "case3-combined.yaml")
    p.add_argument(
        "--lockstep",
        action="store_true",
        help="emulator advances one period per command (deterministic) instead of real time",
    )


def _um(v: Any) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    return f"{v * 1e6:9.2f}"


def _ms(v: Any) -> str:
    return "never" if v is None or (isinstance(v, float) and math.isinf(v)) else f"{v * 1e3:.0f}"


def _line(label: str, mode: str, row: dict[str, Any], extra: str = "") -> str:
    ev = row.get("events") or []
    peaks = " ".join(_um(e["peak_error_m"]).strip() for e in ev)
    rec = " ".join(_ms(e["recovery_s"]) for e in ev)
    return (
        f"{label:<22} {mode:<6} {_um(row.get('rms_error_m'))} {_um(row.get('pre_fault_max_m'))} "
        f"{row.get('switches', '—'):>8}  {peaks:<16} {rec:<12} {extra}"
    )


def _hil(args: argparse.Namespace) -> dict[str, tuple[dict[str, Any], str]]:
    out: dict[str, tuple[dict[str, Any], str]] = {}
    for mode in MODES:
        d = args.out / mode
        print(f"running {args.scenario.name} with {mode}: firmware-sim + controller + logger ...", flush=True)
        res = execute(RunPlan(scenario_path=args.scenario, mode=mode, out_dir=d, lockstep=args.lockstep))
        check_exit_codes(res)
        row = metrics_from_run(d, plot=(mode == "mmac"))
        summ = json.loads((d / "controller-summary.json").read_text())
        trips = int(summ.get("watchdog_trips", 0)) - end_trip(summ)
        extra = (
            f"watchdog trips {trips}, overruns {summ.get('stats', {}).get('overruns')}, "
            f"skipped periods {summ.get('skipped_periods', 0)}"
        )
        out[mode] = (row, extra)
    return out


def _verdict(hil: dict[str, tuple[dict[str, Any], str]]) -> RealtimeVerdict:
    """One verdict for the demo's runs (from their metrics rows), the reasons named by mode."""
    return combine(
        {
            mode: RealtimeVerdict(bool(row["realtime_valid"]), row["realtime_reasons"])
            for mode, (row, _) in hil.items()
        }
    )


def run(args: argparse.Namespace) -> int:
    require("plot", "ehpss-hil demo (its figures)")
    print("== configuration ==")
    for f in [*sorted((PROJECT_ROOT / "configs").glob("*.yaml")), args.scenario]:
        print(f"{f.name}: {check_config.summarize(f)}")
    sc = load_scenario(args.scenario)
    print(f"\n== {sc.name}: {sc.description} ==")
    hil: dict[str, tuple[dict[str, Any], str]] = {}
    try:
        hil = _hil(args)
    except BusUnavailableError as exc:
        print(f"two-process run not possible here: {exc}\n(showing the offline simulation only)")
    kind = "lockstep" if args.lockstep else "real time"
    verdict = _verdict(hil) if hil else None
    if verdict is not None:
        print(f"\n{verdict.line()}")
    print(
        f"\n{'run':<22} {'mode':<6} {'RMS µm':>9} {'pre µm':>9} {'switches':>8}  "
        f"{'peaks µm':<16} {'recov ms':<12}"
    )
    for mode in MODES:
        if mode in hil:
            row, extra = hil[mode]
            print(_line(f"2 processes, {kind}", mode, row, extra))
        sim = compute_metrics(run_scenario(sc, mode)).to_json()
        print(_line("offline lockstep sim", mode, sim))
    if hil:
        print(
            f"\nlogs: {args.out}/<mode>/bus.log (candump -L; also controller.log, emulator.log), "
            f"metrics: {args.out}/<mode>/metrics.json"
        )
        print(f"report + figures: {args.out}/mmac/report/report.md, {args.out}/mmac/report/figures/")
        print(f"replay: ehpss-hil replay {args.out}/mmac/controller.log")
    return 0 if verdict is None or verdict.valid else REALTIME_INVALID_EXIT
