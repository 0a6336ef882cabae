"""``ehpss-hil bench fmu``: the FMU plant (fmpy) against the built-in nonlinear plant the test FMU
is built from, and the emulator's throughput with it (docs/fmu.md).

Builds the test FMU (pythonfmu around our nonlinear plant, :mod:`ehpss_hil.physics.fmutest`)
into a temporary folder, then

* equivalence: the paper's cases 1–3 in lockstep with every mode, once with ``plant: {model:
  nonlinear}`` and once with the FMU: the RMS of the piston-position difference over the RMS
  piston position, and the relative difference of the tracking RMS error; each ≤
  :data:`TARGET_RMS_DIFF`;
* throughput: the emulation alone (plant, sensors, fault schedule: ``PlantEmulation.measure`` +
  ``advance`` per sample, process time on one core) with the FMU and with the built-in plant,
  target ≥ :data:`TARGET_REAL_TIME` × real time with the FMU; the simulator's speed (controller
  and emulation) for information.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import PROJECT_ROOT
from ..blas import limit_blas_threads
from ..control.registry import MODES
from ..emulation import PlantEmulation
from ..physics.fmumap import FmuMap
from ..physics.load import load_params
from ..physics.plantspec import PlantSpec
from ..report.metrics import compute_metrics
from ..scenario import Scenario, load_scenario
from .common import Scorecard, write_json

NAME = "fmu"
HELP = "the FMU plant (fmpy): equivalence with the built-in nonlinear plant on cases 1–3, throughput"

#: the paper's cases the equivalence runs on (scenarios/<name>.yaml)
CASES = ("case1-loe", "case2-drift", "case3-combined")
#: largest relative RMS difference FMU vs built-in plant (position, and tracking RMS error)
TARGET_RMS_DIFF = 0.01
#: the emulator's throughput with the FMU plant (× real time, one core, offline)
TARGET_REAL_TIME = 20.0


@dataclass(frozen=True)
class Equivalence:
    """One case and mode with the built-in plant and with the FMU."""

    case: str
    mode: str
    #: RMS(x_fmu − x_builtin) / RMS(x_builtin), piston position (1)
    position_diff: float
    #: tracking RMS error (m): built-in plant, FMU
    rms_builtin_m: float
    rms_fmu_m: float

    @property
    def rms_diff(self) -> float:
        """|RMS error with the FMU − with the built-in plant| / the built-in's (1)."""
        return abs(self.rms_fmu_m - self.rms_builtin_m) / self.rms_builtin_m

    @property
    def ok(self) -> bool:
        """Both differences within :data:`TARGET_RMS_DIFF`."""
        return self.position_diff <= TARGET_RMS_DIFF and self.rms_diff <= TARGET_RMS_DIFF


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-C", "--controller", action="append", metavar="MODE", help="modes (default: all)")
    p.add_argument("--case", action="append", metavar="NAME", help=f"cases (default: {', '.join(CASES)})")
    p.add_argument(
        "-n", "--samples", type=int, default=20000, help="emulation samples per timing (best of 3)"
    )
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


def fmu_spec(fmu: Path, fmap: dict[str, str]) -> PlantSpec:
    """``plant: {model: fmu, path: fmu, fmu_map: fmap}`` (checked against the FMU)."""
    return PlantSpec(model="fmu", path=str(fmu), fmu_map=FmuMap(**fmap)).loaded()


def equivalence(sc: Scenario, spec: PlantSpec, mode: str) -> Equivalence:
    """``sc`` in lockstep with ``mode`` on the built-in nonlinear plant and on ``spec``."""
    from ..sim.lockstep import run_scenario

    prm = load_params()
    builtin = run_scenario(replace(sc, plant=PlantSpec(model="nonlinear")), mode, prm)
    fmu = run_scenario(replace(sc, plant=spec), mode, prm)
    x0, x1 = builtin.x_true_m, fmu.x_true_m
    diff = float(np.sqrt(np.mean((x1 - x0) ** 2)) / np.sqrt(np.mean(x0**2)))
    return Equivalence(
        sc.name, mode, diff, compute_metrics(builtin).rms_error_m, compute_metrics(fmu).rms_error_m
    )


def emulation_speed(spec: PlantSpec, samples: int) -> float:
    """× real time of the emulation alone on ``spec`` (one core): best of three runs of
    ``samples`` samples on a 1 mm, 5 rad/s sine's worth of current."""
    sc = Scenario(name="bench-fmu", duration_s=3600.0, plant=spec)
    emu = PlantEmulation(load_params(), sc)
    current = [2e-5 * math.sin(2.0 * math.pi * 5.0 * k * sc.sample_time_s) for k in range(samples)]
    best = math.inf
    for _ in range(3):
        emu.reset()
        t0 = time.process_time()
        for i in current:
            emu.measure()
            emu.advance(i)
        best = min(best, time.process_time() - t0)
    return samples * sc.sample_time_s / best


def _equivalence_table(spec: PlantSpec, cases: list[str], modes: list[str], card: Scorecard) -> list[dict]:
    rows: list[dict] = []
    print(
        f"{'case':16s} {'mode':11s} {'RMS µm built-in':>16s} {'RMS µm FMU':>11s} {'ΔRMS %':>8s} {'Δx %':>9s}"
    )
    for case in cases:
        sc = load_scenario(PROJECT_ROOT / "scenarios" / f"{case}.yaml")
        for mode in modes:
            e = equivalence(sc, spec, mode)
            verdict = card.mark(e.ok, f"{case} {mode}: FMU differs from the built-in plant")
            print(
                f"{case:16s} {mode:11s} {e.rms_builtin_m * 1e6:16.3f} {e.rms_fmu_m * 1e6:11.3f} "
                f"{100 * e.rms_diff:8.4f} {100 * e.position_diff:9.2e} {verdict}"
            )
            rows.append({**e.__dict__, "rms_diff": e.rms_diff, "ok": e.ok})
    return rows


def run(args: argparse.Namespace) -> Scorecard:
    from ..physics.fmutest import TEST_FMU_MAP, build_test_fmu
    from ..sim.lockstep import run_scenario

    limit_blas_threads(1)
    card = Scorecard()
    modes = args.controller or list(MODES)
    cases = args.case or list(CASES)
    with tempfile.TemporaryDirectory(prefix="ehpss-bench-fmu-") as tmp:
        spec = fmu_spec(build_test_fmu(Path(tmp)), TEST_FMU_MAP)
        print(f"test FMU: {Path(spec.path).name} (our nonlinear plant, pythonfmu), lockstep, target ≤ 1 %")
        rows = _equivalence_table(spec, cases, modes, card)
        fmu_rt = emulation_speed(spec, args.samples)
        builtin_rt = emulation_speed(PlantSpec(model="nonlinear"), args.samples)
        sc = replace(load_scenario(PROJECT_ROOT / "scenarios" / "case1-loe.yaml"), plant=spec)
        sim_rt = compute_metrics(run_scenario(sc, "mmac", load_params())).speed
    verdict = card.mark(fmu_rt >= TARGET_REAL_TIME, f"emulation with the FMU at {fmu_rt:.0f}× real time")
    print(
        f"emulation (plant + sensors + faults), one core: FMU {fmu_rt:.0f}× real time {verdict} "
        f"(target ≥ {TARGET_REAL_TIME:g}×), built-in nonlinear {builtin_rt:.0f}×; "
        f"simulator (mmac + emulation) with the FMU {sim_rt:.0f}×"
    )
    write_json(
        args.json,
        {
            "equivalence": rows,
            "emulation_real_time": {"fmu": fmu_rt, "builtin_nonlinear": builtin_rt},
            "sim_real_time_mmac_fmu": sim_rt,
            "targets": {"rms_diff": TARGET_RMS_DIFF, "real_time": TARGET_REAL_TIME},
        },
    )
    return card
