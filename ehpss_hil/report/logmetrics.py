"""The metrics of a logged run (:class:`~.logdata.LogRun`): the docs/design.md §10 metrics
(:mod:`.metrics`, one implementation) where the log has ground truth, and what a log gives
regardless (counters from CTRL_STATUS and CTRL_STATS, rejected frames, the sensor-based error)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..codec import Verdict
from .logclock import unwrap_counter
from .logdata import LogRun
from .metrics import RunMetrics, compute_metrics
from .result import SimResult

__all__ = ["LogMetrics", "log_metrics", "verdict_summary"]


def verdict_summary(run: LogRun) -> dict[str, int]:
    """Frames rejected while decoding the log, by verdict name (all frame names summed)."""
    out: dict[str, int] = {}
    for per in run.verdicts.values():
        for v, n in per.items():
            if not Verdict[v].usable:
                out[v] = out.get(v, 0) + n
    return out


@dataclass
class LogMetrics:
    """docs/design.md §10 metrics of a log where it has ground truth, and what a log gives regardless.

    ``run``: :class:`RunMetrics` (None without PLANT_TRUTH or without a reference, see
    ``unavailable``); ``extra``: switch counter, overruns, max cycle time (s), rejected frames,
    sensor-based RMS (y_s − y_m, m: an indication only, the sensor may be faulty).
    """

    run: RunMetrics | None
    extra: dict[str, Any]
    unavailable: list[str]


def _counter_span(v: np.ndarray, modulo: int) -> int:
    return int(unwrap_counter(v.astype(np.int64), modulo)[-1] - int(v[0])) if len(v) else 0


def log_metrics(run: LogRun) -> LogMetrics:
    """Metrics of a :class:`LogRun` (NaN gaps in x_true are held from the previous sample)."""
    r, st, stats = run.result, run.frames.get("CTRL_STATUS"), run.frames.get("CTRL_STATS")
    extra: dict[str, Any] = {"samples": len(r.t_s), "rejected_frames": verdict_summary(run)}
    if st is not None and len(st["t_s"]):
        extra["switches_counter"] = _counter_span(st["Switches"][np.argsort(st["t_s"])], 256)
    if stats is not None and len(stats["t_s"]):
        order = np.argsort(stats["t_s"])
        extra["overruns"] = _counter_span(stats["Overruns"][order], 65536)
        extra["cycle_time_max_s"] = float(np.nanmax(stats["CycleTimeMax"]))
    unavailable: list[str] = []
    if run.has_reference and np.any(np.isfinite(r.y_s_m)):
        e_s = r.y_s_m - r.y_m_m
        extra["sensor_rms_error_m"] = float(np.sqrt(np.nanmean(e_s**2)))
    if not run.has_truth:
        unavailable.append(
            "rms_error_m, pre_fault_max_m, per-event peak_error_m and recovery_s "
            "need x_true: the log has no PLANT_TRUTH (run the emulator with truth on)"
        )
    if not run.has_reference:
        unavailable.append("every tracking metric needs y_m: no reference in the sidecar (pass --scenario)")
    if unavailable or len(r.t_s) == 0:
        return LogMetrics(None, extra, unavailable)
    x = r.x_true_m.copy()
    gaps = ~np.isfinite(x)
    if gaps.any():
        idx = np.where(gaps, 0, np.arange(len(x)))
        np.maximum.accumulate(idx, out=idx)
        x = x[idx]
        x[~np.isfinite(x)] = 0.0
        extra["x_true_filled_samples"] = int(gaps.sum())
    filled = SimResult(**{**r.__dict__, "x_true_m": x})
    return LogMetrics(compute_metrics(filled), extra, unavailable)
