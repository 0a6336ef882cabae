"""``ehpss-hil bench plant``: the cost of one plant sample (µs) for the linear and the nonlinear
plant, and the simulator's speed (× real time, loop CPU time on one core) with each of them.

Target (docs/design.md §11): the simulator at ≥ :data:`TARGET_REAL_TIME` × real time per core.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

from ..blas import limit_blas_threads
from ..physics.load import load_params
from ..physics.plant import Plant, make_plant
from ..physics.plantspec import PlantSpec
from ..report.metrics import compute_metrics
from ..scenario import Reference, Scenario
from .common import Scorecard, write_json

NAME = "plant"
HELP = "plant micro-benchmark (µs per sample) and simulator speed with the linear and nonlinear plant"

#: the offline simulator's speed target (× real time on one core)
TARGET_REAL_TIME = 50.0
#: the plants measured: name → the scenario's plant section
PLANTS: dict[str, PlantSpec] = {
    "linear": PlantSpec(),
    "nonlinear": PlantSpec(model="nonlinear"),
    "nonlinear+friction+overlap": PlantSpec(
        model="nonlinear", coulomb_friction_n=100.0, spool_overlap_m=1e-4
    ),
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-n", "--samples", type=int, default=20000, help="plant samples per timing (best of 3)")
    p.add_argument("--duration", type=float, default=4.0, help="simulated seconds per simulator run")
    p.add_argument(
        "-C", "--controller", action="append", metavar="MODE", help="simulator modes (default nrc, mmac)"
    )
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


def plant_us(plant: Plant, samples: int) -> float:
    """Process time of one :meth:`Plant.step` (µs), best of three runs of ``samples`` steps on a
    1 mm, 5 rad/s sine's worth of current."""
    current = [2e-5 * math.sin(2.0 * math.pi * 5.0 * k * plant.ts_s) for k in range(samples)]
    best = math.inf
    for _ in range(3):
        plant.reset()
        t0 = time.process_time()
        for i in current:
            plant.step(i)
        best = min(best, time.process_time() - t0)
    return best / samples * 1e6


def sim_speed(spec: PlantSpec, mode: str, duration_s: float) -> tuple[float, float]:
    """``(× real time, RMS µm)`` of the fault-free 1 mm, 5 rad/s sine on plant ``spec``: the
    better of two runs after a short one that fills the per-process caches (codec, ZOH maps)."""
    from ..sim.lockstep import run_scenario

    sc = replace(Scenario(name="bench-plant", duration_s=duration_s, reference=Reference()), plant=spec)
    run_scenario(replace(sc, duration_s=min(duration_s, 0.1)), mode, load_params())
    runs = [compute_metrics(run_scenario(sc, mode, load_params())) for _ in range(2)]
    return max(m.speed for m in runs), runs[0].rms_error_m * 1e6


def run(args: argparse.Namespace) -> Scorecard:
    limit_blas_threads(1)
    card = Scorecard()
    modes = args.controller or ["nrc", "mmac"]
    base = load_params().plant
    rows = []
    print(f"{'plant':28s} {'µs/sample':>10s}" + "".join(f" {m + ' ×RT':>16s} {'RMS µm':>8s}" for m in modes))
    for name, spec in PLANTS.items():
        us = plant_us(make_plant(spec, base, 1e-3), args.samples)
        row: dict[str, object] = {"plant": name, "plant_us_per_sample": us}
        line = f"{name:28s} {us:10.2f}"
        for m in modes:
            speed, rms = sim_speed(spec, m, args.duration)
            row[f"{m}.real_time"], row[f"{m}.rms_um"] = speed, rms
            verdict = card.mark(speed >= TARGET_REAL_TIME, f"{name} {m} sim speed {speed:.0f}× real time")
            line += f" {speed:10.0f}× {verdict:4s} {rms:8.2f}"
        rows.append(row)
        print(line)
    print(f"target: the simulator ≥ {TARGET_REAL_TIME:g}× real time per core (1 kHz: ≤ 20 µs per sample)")
    write_json(args.json, {"rows": rows, "target_real_time": TARGET_REAL_TIME})
    return card
