"""One campaign run: its scenario simulated with every mode → the metric columns of its row.

:func:`execute` is what a worker runs (a local process or a Dask worker): a module-level function
of a picklable :class:`RunTask`, with no state but the per-process caches of the simulator. Its
metrics are deterministic; the timing beside them is not and stays out of the table.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import Any

from ..control.tuning import ControlTuning
from ..physics.load import load_params
from ..physics.params import Params
from ..report.metrics import RunMetrics, compute_metrics
from ..scenario import Scenario
from ..sim.lockstep import run_scenario

#: the per-mode metric columns of a row, in order (docs/design.md §10; ``*_s``, ``*_m`` in SI)
METRIC_COLUMNS = (
    "rms_error_m",
    "pre_fault_max_m",
    "max_error_m",
    "switches",
    "peak_error_m",
    "recovery_s",
    "final_recovery_s",
    "event_switches",
    "active_spool",
    "active_position",
    "fallback_s",
)


@dataclass(frozen=True)
class RunTask:
    """What a worker needs for one run: the finished scenario and the modes to simulate."""

    index: int
    run_hash: str
    scenario: Scenario
    modes: tuple[str, ...]
    transport: str = "quantize"
    #: the controller's tuning (None: the defaults)
    tuning: ControlTuning | None = None


@functools.cache
def _params() -> Params:
    return load_params()


def metric_columns(m: RunMetrics) -> dict[str, Any]:
    """One mode's metrics as flat columns: the run's RMS, pre-fault and worst error (m) and
    switches; over its fault events the worst peak (m), the longest recovery (s, inf: never),
    the recovery after the last event, the switches inside events; the model slots active at
    the end (-1: none, or no bank); the time on the nominal fallback (s)."""
    last = m.events[-1] if m.events else None
    active = (last.active_model if last else None) or {}
    joint = active.get("joint", -1)
    return {
        "rms_error_m": m.rms_error_m,
        "pre_fault_max_m": m.pre_fault_max_m,
        "max_error_m": m.max_error_m,
        "switches": m.switches,
        "peak_error_m": max((e.peak_error_m for e in m.events), default=0.0),
        "recovery_s": max((e.recovery_s for e in m.events), default=0.0),
        "final_recovery_s": last.recovery_s if last else 0.0,
        "event_switches": sum(e.switches for e in m.events),
        "active_spool": active.get("spool", joint),
        "active_position": active.get("position", joint),
        "fallback_s": m.fallback_s,
    }


def execute(task: RunTask) -> dict[str, Any]:
    """Simulate ``task`` with each mode: ``{"run_hash", "index", "metrics": {"mode.metric": v},
    "timing": {"wall_s", "sim_s", "cpu_s": {mode: s}}}`` (timing: this run's wall time, simulated
    seconds per mode and each mode's loop CPU time)."""
    t0 = time.perf_counter()
    metrics: dict[str, Any] = {}
    cpu: dict[str, float] = {}
    for mode in task.modes:
        res = run_scenario(task.scenario, mode, _params(), task.tuning, task.transport)
        cpu[mode] = res.cpu_s
        for key, value in metric_columns(compute_metrics(res)).items():
            metrics[f"{mode}.{key}"] = value
    return {
        "run_hash": task.run_hash,
        "index": task.index,
        "metrics": metrics,
        "timing": {"wall_s": time.perf_counter() - t0, "sim_s": task.scenario.duration_s, "cpu_s": cpu},
    }
