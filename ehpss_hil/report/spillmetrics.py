"""The docs/design.md §10 metrics of a run too long to hold: per-sample values on disk, the
metrics :func:`~.metrics.compute_metrics` computes, read back in blocks.

:class:`Spill` appends, per sample, what the metrics and the event labels read — |x − y_m| (x
held over samples without PLANT_TRUTH, as :func:`~.logmetrics.log_metrics` holds it), the active
models and their switches, the true gains and the stuck flag — to files in a scratch directory
(≈ 50 bytes a sample) and keeps running sums (the RMS, the sensor-based RMS). Once the event
times are known, :func:`spill_metrics` computes each event's peak, recovery, switches and active
model from those files, :data:`BLOCK` samples at a time: the same definitions, the same values
(the RMS up to the order of its summation).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..codec import Verdict
from ..scenario import Scenario
from .annotate import event_labels
from .logmetrics import LogMetrics
from .metrics import PEAK_WINDOW_S, RECOVERY_BAND_M, EventMetrics, RunMetrics, _active
from .result import SimResult

#: samples read back at a time (8 MB of float64)
BLOCK = 1 << 20
#: per-sample files and their types
_FILES = {
    "abs_err": np.float64,
    "spool": np.int8,
    "position": np.int8,
    "sw_spool": np.int8,
    "sw_any": np.int8,
    "k_loe": np.float64,
    "k_q": np.float64,
    "k_dft": np.float64,
    "stuck": np.int8,
}


class Spill:
    """Per-sample files of one run in ``folder`` and the running sums (module docstring)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.n = 0
        self.sum_sq = 0.0
        self.max_err = 0.0
        self.sensor_sq, self.sensor_n, self.sensor_any = 0.0, 0, False
        self.filled = 0
        self.has_truth = False
        self.joint = True  # active_spool == active_position everywhere: a joint bank
        self._x: float | None = None  # the last x with ground truth (m)
        self._models: tuple[int, int] | None = None
        for name in _FILES:
            (folder / name).write_bytes(b"")

    def _append(self, name: str, v: np.ndarray) -> None:
        with open(self.folder / name, "ab") as f:
            f.write(np.ascontiguousarray(v, dtype=_FILES[name]).tobytes())

    def add(self, r: SimResult) -> None:
        """Append the samples of one chunk (consecutive with the previous one)."""
        n = len(r.t_s)
        x = r.x_true_m.copy()
        gaps = ~np.isfinite(x)
        self.filled += int(gaps.sum())
        if gaps.any():  # held from the previous sample with truth (0 before the first one)
            idx = np.where(gaps, -1, np.arange(n))
            np.maximum.accumulate(idx, out=idx)
            prev = 0.0 if self._x is None else self._x
            x = np.where(idx >= 0, x[np.clip(idx, 0, None)], prev)
        if np.any(~gaps):
            self._x = float(x[np.flatnonzero(~gaps)[-1]])
        err = x - r.y_m_m
        self.sum_sq += float(np.sum(err**2))
        e = np.abs(err)
        self.max_err = max(self.max_err, float(np.max(e)))
        y_s = r.y_s_m - r.y_m_m
        ok = np.isfinite(y_s)
        self.sensor_any |= bool(np.any(np.isfinite(r.y_s_m)))
        self.sensor_sq += float(np.sum(y_s[ok] ** 2))
        self.sensor_n += int(ok.sum())
        truth = len(r.stuck) == n
        self.has_truth |= truth
        sp, ps = r.active_spool, r.active_position
        self.joint &= bool(np.array_equal(sp, ps))
        prev_sp, prev_ps = self._models if self._models is not None else (int(sp[0]), int(ps[0]))
        ch_sp = np.diff(np.concatenate(([prev_sp], sp))) != 0
        ch_ps = np.diff(np.concatenate(([prev_ps], ps))) != 0
        self._models = (int(sp[-1]), int(ps[-1]))
        for name, v in (
            ("abs_err", e),
            ("spool", sp),
            ("position", ps),
            ("sw_spool", ch_sp),
            ("sw_any", ch_sp | ch_ps),
            ("k_loe", r.true_k_loe),
            ("k_q", r.true_k_q),
            ("k_dft", r.true_k_dft),
            ("stuck", r.stuck if truth else np.zeros(n, bool)),
        ):
            self._append(name, v)
        self.n += n

    def read(self, name: str, lo: int, hi: int) -> np.ndarray:
        """Samples ``lo``…``hi − 1`` of file ``name``."""
        dt = np.dtype(_FILES[name])
        lo, hi = max(lo, 0), min(hi, self.n)
        if hi <= lo:
            return np.zeros(0, dt)
        return np.fromfile(self.folder / name, dtype=dt, count=hi - lo, offset=lo * dt.itemsize)

    def blocks(self, name: str, lo: int, hi: int) -> Iterator[tuple[int, np.ndarray]]:
        """``(first sample, values)`` of ``name`` over ``lo``…``hi − 1``, :data:`BLOCK` at a time."""
        for a in range(lo, hi, BLOCK):
            yield a, self.read(name, a, min(a + BLOCK, hi))

    def mapped(self, name: str) -> np.ndarray:
        """File ``name`` mapped read-only (for the few samples the event labels look at)."""
        if self.n == 0:
            return np.zeros(0, _FILES[name])
        return np.memmap(self.folder / name, dtype=_FILES[name], mode="r", shape=(self.n,))

    def result(self, events: tuple[float, ...], ts_s: float) -> SimResult:
        """A :class:`SimResult` over the files (the true gains, the stuck flag, the models):
        what :func:`~.annotate.event_labels` and the event metrics read, nothing loaded."""
        z = np.zeros(0)
        stuck = self.mapped("stuck").view(np.bool_) if self.has_truth else np.zeros(0, bool)
        return SimResult(
            "log", "", ts_s, events, self.mapped("abs_err"), z, z, z, z, z, z,
            self.mapped("spool"), self.mapped("position"), z, z, np.zeros((0, 16)),
            self.mapped("k_loe"), self.mapped("k_q"), self.mapped("k_dft"), np.zeros(0, bool),
            stuck=stuck,
        )  # fmt: skip

    def event_times(
        self,
        bus: tuple[float, ...],
        sc: Scenario | None,
        injections: tuple[tuple[float, str], ...],
        ts: float,
    ) -> tuple[float, ...]:
        """The run's event times (s), as :func:`~.logdata.load_log_run` sets them: the changes
        on the bus, named by the scenario's events, plus the injections."""
        times = bus
        if sc is not None and self.n:
            times = tuple(t for t, _ in event_labels(self.result(bus, ts), sc.events))
        if injections:
            times = tuple(sorted({*times, *(t for t, _ in injections)}))
        return times


def _recovery(spill: Spill, k0: int, k1: int, ts: float) -> float:
    """:func:`~.metrics.recovery_time_s` of samples ``k0``…``k1 − 1``, read from the end."""
    for a in range(k1, k0, -BLOCK):
        lo = max(k0, a - BLOCK)
        out = np.flatnonzero(spill.read("abs_err", lo, a) >= RECOVERY_BAND_M)
        if len(out):
            last = lo + int(out[-1])
            return math.inf if last == k1 - 1 else float((last - k0 + 1) * ts)
    return 0.0


def _max(spill: Spill, lo: int, hi: int) -> float:
    return max((float(v.max()) for _, v in spill.blocks("abs_err", lo, hi) if len(v)), default=0.0)


def _count(spill: Spill, name: str, lo: int, hi: int) -> int:
    return sum(int(np.count_nonzero(v)) for _, v in spill.blocks(name, lo, hi))


def run_metrics(
    spill: Spill, events: tuple[float, ...], ts: float, scenario: str, controller: str
) -> RunMetrics:
    """:func:`~.metrics.compute_metrics` of the spilled run (its definitions, block by block)."""
    n = spill.n
    starts = [min(round(t / ts), n) for t in events]
    first = starts[0] if starts else n
    marks = "sw_spool" if spill.joint else "sw_any"
    view = spill.result(events, ts)
    out = []
    for i, k0 in enumerate(starts):
        k1 = starts[i + 1] if i + 1 < len(starts) else n
        if k1 <= k0:
            continue
        kp = min(k0 + round(PEAK_WINDOW_S / ts), n)
        out.append(
            EventMetrics(
                t_s=events[i],
                peak_error_m=float(spill.read("abs_err", k0, kp).max()),
                recovery_s=_recovery(spill, k0, k1, ts),
                active_model=_active(view, k1 - 1),
                switches=_count(spill, marks, k0, k1),
            )
        )
    return RunMetrics(
        scenario=scenario,
        controller=controller,
        rms_error_m=math.sqrt(spill.sum_sq / n),
        pre_fault_max_m=_max(spill, 0, first) if first > 0 else 0.0,
        switches=_count(spill, marks, 0, n),
        events=out,
        duration_s=n * ts,
        max_error_m=spill.max_err,
    )


def spill_metrics(
    spill: Spill,
    events: tuple[float, ...],
    ts: float,
    has_truth: bool,
    has_ref: bool,
    names: tuple[str, str] | None,
    counters: dict[str, Any],
    verdicts: dict[str, dict[str, int]],
) -> LogMetrics:
    """:func:`~.logmetrics.log_metrics` of a spilled run: the same keys, notes and metrics;
    ``names``: the run's (scenario, controller), None without samples."""
    rejected: dict[str, int] = {}
    for per in verdicts.values():
        for v, c in per.items():
            if not Verdict[v].usable:
                rejected[v] = rejected.get(v, 0) + c
    extra: dict[str, Any] = {"samples": spill.n, "rejected_frames": rejected, **counters}
    if has_ref and spill.sensor_any:
        extra["sensor_rms_error_m"] = (
            math.sqrt(spill.sensor_sq / spill.sensor_n) if spill.sensor_n else math.nan
        )
    unavailable: list[str] = []
    if not has_truth:
        unavailable.append(
            "rms_error_m, pre_fault_max_m, per-event peak_error_m and recovery_s "
            "need x_true: the log has no PLANT_TRUTH (run the emulator with truth on)"
        )
    if not has_ref:
        unavailable.append("every tracking metric needs y_m: no reference in the sidecar (pass --scenario)")
    if unavailable or spill.n == 0 or names is None:
        return LogMetrics(None, extra, unavailable)
    if spill.filled:
        extra["x_true_filled_samples"] = spill.filled
    return LogMetrics(run_metrics(spill, events, ts, *names), extra, unavailable)
