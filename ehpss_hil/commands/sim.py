"""``ehpss-hil sim SCENARIO… --controller MODE…``: lockstep simulation, metrics table, JSON, plot."""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from ..codec import FrameCodec
from ..control.registry import MODES
from ..extras import require
from ..report.metrics import RunMetrics
from ..scenario import Scenario
from ..sim.jobs import Job, JobOutcome, default_jobs, run_jobs, scenario_paths
from ..sim.lockstep import TRANSPORTS

NAME = "sim"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenarios", nargs="+", help="scenario YAML files (or directories of them)")
    p.add_argument(
        "--controller",
        "-C",
        action="append",
        choices=MODES,
        metavar="MODE",
        help=f"controller mode, repeatable ({', '.join(MODES)}; default mmac)",
    )
    p.add_argument("--json", metavar="FILE", help="write the docs/design.md §10 metric rows as JSON")
    p.add_argument(
        "--plot",
        metavar="FILE.png",
        help="figure like the paper's Figs 4-7, every mode of a scenario overlaid, written to FILE "
        "(several scenarios: FILE-<scenario>.png each); prints every file written",
    )
    p.add_argument(
        "--transport",
        choices=TRANSPORTS,
        default="quantize",
        help="frame layer: DBC quantization (fast) or real encoded frames with E2E",
    )
    p.add_argument(
        "--protocol",
        metavar="CONTROLLER.yaml",
        default="",
        help="speak the protocol profile of this controller config on both sides (implies "
        "--transport frames), e.g. configs/controller-vendor.yaml",
    )
    p.add_argument(
        "--params",
        metavar="PARAMS.yaml",
        default="",
        help="the controller's model params (its models and y_m; default configs/params.yaml); "
        "the emulated plant stays configs/params.yaml under each scenario's plant: section",
    )
    p.add_argument(
        "--jobs",
        "-j",
        type=int,
        default=default_jobs(),
        help="worker processes for several runs (default: all cores)",
    )


def _fmt_s(v: float) -> str:
    return "never" if math.isinf(v) else f"{v * 1e3:.0f}"


def format_table(rows: list[RunMetrics]) -> str:
    """A fixed-width table of RMS, pre-fault max, switches, worst event peak and recovery, speed."""
    head = (
        f"{'scenario':22s} {'controller':10s} {'RMS µm':>9s} {'pre µm':>7s} {'sw':>4s} "
        f"{'peak µm':>9s} {'rec ms':>7s} {'speed':>7s}"
    )
    lines = [head, "-" * len(head)]
    for m in rows:
        peak = max((e.peak_error_m for e in m.events), default=0.0)
        rec = max((e.recovery_s for e in m.events), default=0.0)
        lines.append(
            f"{m.scenario[:22]:22s} {m.controller:10s} {m.rms_error_m * 1e6:9.2f} "
            f"{m.pre_fault_max_m * 1e6:7.1f} {m.switches:4d} {peak * 1e6:9.1f} "
            f"{_fmt_s(rec):>7s} {m.speed:6.0f}×"
        )
    return "\n".join(lines)


def speed_line(rows: list[RunMetrics], wall_s: float, processes: int) -> str:
    """Simulated seconds per wall second, for the campaign and per run (one core each)."""
    simulated = sum(m.duration_s for m in rows)
    per_run = [m.speed for m in rows if m.speed > 0]
    text = (
        f"{len(rows)} run(s): {simulated:.1f} s simulated in {wall_s:.2f} s wall = "
        f"{simulated / wall_s:.0f}× real time on {processes} process(es)"
    )
    if per_run:
        text += f"; per run (loop CPU time, one core): {min(per_run):.0f}–{max(per_run):.0f}×"
    return text


def plant_line(paths: list[str], params_file: str, model_differs: bool) -> str:
    """Which plant the runs drove against which model: ``plant = model`` (a best case) unless a
    scenario's ``plant:`` section or ``--params`` (``model_differs``) made them differ."""
    from ..scenario import load_scenario

    model = f"controller params {params_file or 'configs/params.yaml'}"
    own = {(sc := load_scenario(p)).name: sc.plant.describe() for p in paths}
    own = {name: text for name, text in own.items() if text != "linear"}
    if not own and not model_differs:
        return f"plant = model ({model}; a best case)"
    shown = "; ".join(f"{name}: {text}" for name, text in own.items())
    rest = "plant configs/params.yaml" + (" under each scenario's plant: section" if own else "")
    return f"plant ≠ model ({model}, {rest}){': ' + shown if shown else ''}"


def plot_name(base: Path, many: bool, scenario: str) -> Path:
    """Where ``--plot base`` writes the figure of ``scenario``: ``base`` itself for one scenario,
    ``base-<scenario>.png`` (same suffix) when several are drawn."""
    return base.with_name(f"{base.stem}-{scenario}{base.suffix or '.png'}") if many else base


def write_plots(outcomes: list[JobOutcome], base: Path) -> list[Path]:
    """One figure per scenario with every mode run on it overlaid (:func:`plot_name`)."""
    from ..report.figures import RunView, plot_runs
    from ..scenario import load_scenario

    by_scenario: dict[str, list[RunView]] = {}
    for o in outcomes:
        if o.result is None:
            continue
        sc = o.job.scenario if isinstance(o.job.scenario, Scenario) else load_scenario(o.job.scenario)
        by_scenario.setdefault(o.result.scenario, []).append(RunView.of(o.result, sc.events))
    return [
        plot_runs(views, plot_name(base, len(by_scenario) > 1, name)) for name, views in by_scenario.items()
    ]


def _check_travel(codec: FrameCodec, protocol_config: str, paths: list[str]) -> None:
    """Each scenario's reference fits the profile's position field (a ConfigError naming it)."""
    from ..config import load_controller_config
    from ..protocol.travel import check_position_range, reference_extent_m
    from ..scenario import load_scenario

    cfg = load_controller_config(protocol_config)
    for p in paths:
        travel = reference_extent_m(load_scenario(p).reference)
        check_position_range(codec, travel, f"the reference of {p}", protocol_config, cfg)


def run(args: argparse.Namespace) -> int:
    if args.plot:
        require("plot", "--plot")
    modes = args.controller or ["mmac"]
    paths = scenario_paths(args.scenarios)
    transport = "frames" if args.protocol else args.transport
    if args.protocol:
        from ..sim.lockstep import config_codec

        codec = config_codec(args.protocol)  # a bad config or map: exit 2 before any run
        _check_travel(codec, args.protocol, paths)
    params = plant = None
    if args.params:
        from ..physics.load import load_params

        params, plant = load_params(args.params), load_params().plant  # bad file: exit 2
    jobs = [
        Job(p, m, transport, keep_result=bool(args.plot), protocol_config=args.protocol)
        for p in paths
        for m in modes
    ]
    t0 = time.perf_counter()
    outcomes = run_jobs(jobs, args.jobs, params, plant_params=plant)
    wall = time.perf_counter() - t0
    rows = [o.metrics for o in outcomes]
    print(format_table(rows))
    print(plant_line(paths, args.params, params is not None and params.plant != plant))
    print(speed_line(rows, wall, min(args.jobs, len(jobs))))
    if args.json:
        Path(args.json).write_text(json.dumps([m.to_json() for m in rows], indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        for out in write_plots(outcomes, Path(args.plot)):
            print(f"wrote {out}")
    return 0
