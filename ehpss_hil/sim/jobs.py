"""Jobs: many (scenario, controller) runs on all cores, results in submission order (`ehpss-hil sim`)."""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..blas import limit_blas_threads
from ..control.tuning import ControlTuning
from ..errors import ConfigError
from ..physics.load import load_params
from ..physics.params import Params, PlantParams
from ..report.metrics import RunMetrics, compute_metrics
from ..report.result import SimResult
from ..scenario import Scenario, load_scenario
from .lockstep import run_scenario


@dataclass(frozen=True)
class Job:
    """One run: a scenario file (or loaded scenario) and a controller mode."""

    scenario: str | Scenario
    mode: str
    transport: str = "quantize"
    keep_result: bool = False
    #: a controller config whose protocol profile both sides speak (frames transport); "": native
    protocol_config: str = ""
    #: a native DBC other than the shipped one on both sides (another scaling); "": the shipped one
    dbc: str = ""


@dataclass
class JobOutcome:
    """The metrics of a run, and its arrays when the job asked to keep them."""

    job: Job
    metrics: RunMetrics
    result: SimResult | None


_PARAMS: Params | None = None
_TUNING: ControlTuning | None = None
_PLANT: PlantParams | None = None


def _init(params: Params | None, tuning: ControlTuning | None, plant: PlantParams | None = None) -> None:
    global _PARAMS, _TUNING, _PLANT
    _PARAMS = params if params is not None else load_params()
    _TUNING = tuning
    _PLANT = plant


def _run(job: Job) -> JobOutcome:
    sc = job.scenario if isinstance(job.scenario, Scenario) else load_scenario(job.scenario)
    try:
        res = run_scenario(
            sc, job.mode, _PARAMS, _TUNING, job.transport, job.protocol_config, _PLANT, job.dbc
        )
    except ConfigError as exc:  # e.g. a plant section whose mapping fails: name the file
        if exc.source or isinstance(job.scenario, Scenario):
            raise
        raise ConfigError(job.scenario, exc.key_path, exc.reason) from exc
    return JobOutcome(job, compute_metrics(res), res if job.keep_result else None)


def default_jobs() -> int:
    """Worker processes by default: every core."""
    return os.cpu_count() or 1


def run_jobs(
    jobs: Sequence[Job],
    n_jobs: int | None = None,
    params: Params | None = None,
    tuning: ControlTuning | None = None,
    progress: Callable[[int, int], None] | None = None,
    plant_params: PlantParams | None = None,
) -> list[JobOutcome]:
    """Run every job (on ``n_jobs`` processes; 1 = in this process); outcomes in job order.

    ``params``: the controller's (default: configs/params.yaml); ``plant_params``: the emulated
    plant's base under each scenario's ``plant:`` section (default: ``params.plant``).

    ``progress(done, total)`` is called after each finished run.
    """
    n = max(1, min(n_jobs or default_jobs(), len(jobs)))
    limit_blas_threads(1)  # before forking: no spinning BLAS pool to inherit
    out: list[JobOutcome] = []
    if n == 1:
        _init(params, tuning, plant_params)
        for i, job in enumerate(jobs):
            out.append(_run(job))
            if progress:
                progress(i + 1, len(jobs))
        return out
    ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    with ctx.Pool(n, initializer=_init, initargs=(params, tuning, plant_params)) as pool:
        for i, o in enumerate(pool.imap(_run, jobs, chunksize=1)):
            out.append(o)
            if progress:
                progress(i + 1, len(jobs))
    return out


def scenario_paths(items: Sequence[str | Path]) -> list[str]:
    """Scenario files as strings (directories expand to their ``*.yaml``, sorted)."""
    paths: list[str] = []
    for it in items:
        p = Path(it)
        paths.extend(sorted(str(q) for q in p.glob("*.yaml")) if p.is_dir() else [str(p)])
    return paths
