"""``ehpss-hil run SCENARIO``: emulator + controller + bus logger as real processes on one bus.

Prints the realtime verdict first (:mod:`ehpss_hil.runtime.rtverdict`), then a short summary of
the metrics; the JSON is in the run directory. Exit 0; 4 when the processes ended cleanly but
the host did not hold the rate (``realtime_valid`` false: the figures are not the
controller's); 1 a process failed; 2 bad input or output; 3 missing interface.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..canlog import read_sidecar
from ..control.registry import DAEMON_MODES
from ..extras import require
from ..orchestrate import CONTROLLER_YAML, EMULATOR_YAML, RunPlan, check_exit_codes, execute
from ..run_metrics import describe, metrics_from_run
from ..rundir import RUN_LOGS, record_outputs
from ..runtime.rtverdict import REALTIME_INVALID_EXIT, RealtimeVerdict
from ..schema import load_yaml

NAME = "run"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", type=Path, help="scenario YAML (scenarios/case2-drift.yaml, ...)")
    p.add_argument(
        "--mode",
        default="mmac",
        choices=DAEMON_MODES,
        help="the controller's control law: nrc (the paper's PI), smac (one adaptive model), "
        "mmac-paper (the paper's joint bank), mmac (per-channel banks; default)",
    )
    p.add_argument(
        "--interface", choices=("udp_multicast", "socketcan"), help="override the configs' bus.interface"
    )
    p.add_argument("--channel", help="override the configs' bus.channel (vcan0, can0, group)")
    p.add_argument(
        "--out",
        type=Path,
        help="run directory (default out/runs/<scenario>-<mode>); "
        "a non-empty directory that is no run directory is refused",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="use a non-empty --out anyway, replacing only the files a run writes",
    )
    p.add_argument(
        "--lockstep", action="store_true", help="emulator advances one period per VALVE_CMD (deterministic)"
    )
    p.add_argument("--plot", action="store_true", help="also draw the report figures")
    p.add_argument(
        "--controller-config",
        type=Path,
        default=CONTROLLER_YAML,
        help="the controller's config (default configs/controller.yaml; e.g. configs/controller-vendor.yaml)",
    )
    p.add_argument(
        "--emulator-config",
        type=Path,
        default=EMULATOR_YAML,
        help="the emulator's config (default configs/emulator.yaml; e.g. configs/emulator-vendor.yaml)",
    )
    p.add_argument(
        "--watchdog-cycles",
        type=int,
        default=10,
        help="watchdog.timeout_cycles for this run (default 10 on a non-RT bench host; 0 = the config's)",
    )
    p.add_argument(
        "--sensor-age-us",
        type=float,
        default=300.0,
        help="controller phase lock for this run (µs after the sensor frame; default "
        "300; -1 = the config's rt.sensor_age_us)",
    )
    p.add_argument(
        "--strict-watchdog",
        action="store_true",
        help="keep the config's watchdog.auto_recover (default for runs: recover "
        "after watchdog.recovery_cycles fresh cycles)",
    )

    p.add_argument(
        "--monitor",
        type=int,
        metavar="PORT",
        help="serve the live monitor (ehpss-hil monitor) on 127.0.0.1:PORT during the run",
    )
    p.add_argument(
        "--monitor-allow-inject",
        action="store_true",
        help="with --monitor: the page's fault-injection buttons (the emulator accepts FAULT_INJECT)",
    )


def _sends_truth(emulator_yaml: Path) -> bool:
    """PLANT_TRUTH on, except with ``protocol: cia408`` (the run's metrics read native frames,
    which such a run lacks, and say so; ``firmware-sim --truth`` sends PLANT_TRUTH there for the
    rogue-node trials)."""
    data = load_yaml(emulator_yaml)
    return not (isinstance(data, dict) and data.get("protocol") == "cia408")


def run(args: argparse.Namespace) -> int:
    if args.plot:
        require("plot", "--plot")
    out = args.out or Path("out/runs") / f"{args.scenario.stem}-{args.mode}"
    plan = RunPlan(
        scenario_path=args.scenario,
        mode=args.mode,
        out_dir=out,
        interface=args.interface,
        channel=args.channel,
        lockstep=args.lockstep,
        auto_recover=not args.strict_watchdog,
        watchdog_cycles=args.watchdog_cycles or None,
        sensor_age_us=None if args.sensor_age_us < 0 else args.sensor_age_us,
        overwrite=args.overwrite,
        monitor_port=args.monitor,
        monitor_inject=args.monitor_allow_inject,
        controller_yaml=args.controller_config,
        emulator_yaml=args.emulator_config,
        truth=_sends_truth(args.emulator_config),
    )
    res = execute(plan)
    check_exit_codes(res)
    written: list[Path] = []
    try:
        row = metrics_from_run(out, plot=args.plot, written=written)
    finally:
        record_outputs(out, written)
    verdict = RealtimeVerdict(bool(row["realtime_valid"]), list(row["realtime_reasons"]))
    print(verdict.line())
    print("\n".join(describe(row)))
    for log in RUN_LOGS:
        counts = (read_sidecar(out / log) or {}).get("counts") or {}
        if counts.get("dropped"):
            why = ", ".join(f"{k} {n}" for k, n in (counts.get("dropped_by_reason") or {}).items())
            print(f"warning: {log}: {counts['dropped']} lines not written ({why})", file=sys.stderr)
    print(f"run directory: {out} (bus.log, metrics.json, run.json)")
    return 0 if verdict.valid else REALTIME_INVALID_EXIT
