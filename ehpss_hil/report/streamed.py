"""The report of a log of any length in bounded memory: the chunks of :mod:`.logstream`
summed up as they go by.

What needs every sample is kept in the form it needs: the tracking error, the active models and
the true gains go to a scratch file (≈ 50 bytes a sample, on disk, read back in blocks), because
the event windows are known only at the end (a scenario event the bus cannot show is placed at
its time plus the offset of the events that it does show); the metrics are then
:func:`~.metrics.compute_metrics`'s on that file, block by block (:mod:`.spillmetrics`). The
counters (switches, overruns), the fail-safe and fallback intervals and the sensor-based RMS are
running sums; the figures are drawn from a :class:`~.decimate.MinMaxDecimator` view.
"""

from __future__ import annotations

import glob
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..canlog import BadLines, read_sidecar
from ..canlog.reader import FRAME_INDEX, resolve_log
from ..codec import FrameCodec
from ..physics.load import load_params
from ..physics.params import Params
from ..scenario import Scenario
from .annotate import Interval, event_labels
from .decimate import MinMaxDecimator
from .figures import RunView
from .heap import release_freed_memory
from .logdata import LogRun, _dbc_of, _why_empty
from .logmeta import run_info
from .logmetrics import LogMetrics
from .logstream import CHUNK_SAMPLES, ChunkRows, LogStream, StreamState
from .logviews import _names
from .result import SimResult
from .spillmetrics import Spill, spill_metrics

#: a log whose files hold more bytes than this is read in chunks from the start (a candump
#: bench log of :data:`~ehpss_hil.limits.MAX_LOG_SAMPLES` samples is ≈ 80 MB); a smaller one
#: is read whole, and in chunks only when it holds more samples than that after all
STREAM_ABOVE_BYTES = 32 * 2**20


def log_bytes(path: str | os.PathLike[str]) -> int:
    """Bytes of a log's files (file or directory; a candump log with its rotated files)."""
    log = resolve_log(path)
    rotated = [p for p in log.parent.glob(glob.escape(log.name) + ".*") if p.suffix[1:].isdigit()]
    return sum(p.stat().st_size for p in (log, *rotated) if p.is_file())


@dataclass
class Loaded:
    """What ``report`` draws and writes of one log: the run and its metrics, the run the
    figures draw (thinned), and for a streamed log the whole log's view and frame counts."""

    run: LogRun
    metrics: LogMetrics
    drawn: LogRun
    view: RunView | None
    frame_counts: dict[str, int] | None


@dataclass
class StreamedRun:
    """A long log's report data: ``run`` holds the thinned samples the figures draw (its
    metrics, view and frame counts are of every sample)."""

    run: LogRun
    metrics: LogMetrics
    view: RunView
    frame_counts: dict[str, int]


class _Intervals:
    """FAULT and fallback intervals over the chunks (one run of equal codes may span several)."""

    def __init__(self, codec: FrameCodec) -> None:
        self.names = {
            "FAULT": {1 + k: v for k, v in _names(codec, "CTRL_STATUS", "FailsafeReason").items()},
            "fallback": {
                1 + k: ("" if k == 0 else v) for k, v in _names(codec, "CTRL_STATS", "FallbackReason").items()
            },
        }
        self.open: dict[str, tuple[int, float]] = {"FAULT": (0, 0.0), "fallback": (0, 0.0)}
        self.done: dict[str, list[Interval]] = {"FAULT": [], "fallback": []}
        self.t_end = 0.0

    def add(self, ch: ChunkRows) -> None:
        r = ch.result
        t = r.t_s
        st, stats = ch.frames.get("CTRL_STATUS"), ch.frames.get("CTRL_STATS")
        fault, fb = np.zeros(len(t)), np.zeros(len(t))
        if st is not None and len(st["t_s"]):
            state, reason, nom = (
                self._held(ch, st, s) for s in ("State", "FailsafeReason", "NominalFallback")
            )
            fault = np.where(state == 3, 1 + reason, 0)
            why = self._held(ch, stats, "FallbackReason") if stats is not None and len(stats["t_s"]) else 0.0
            fb = np.where(nom > 0.5, 1 + why, 0)
        self._runs("FAULT", t, fault)
        self._runs("fallback", t, fb)
        self.t_end = float(t[-1]) + r.ts_s

    @staticmethod
    def _held(ch: ChunkRows, f: dict[str, np.ndarray], sig: str) -> np.ndarray:
        """``sig`` held on the samples, the frames placed on the controller's time through the
        rows' wall times (:func:`~.logviews.controller_time`, the commands around them)."""
        t_ctrl = np.interp(f["t_s"], ch.t_rows, ch.result.t_s)
        order = np.argsort(t_ctrl, kind="stable")
        t_ctrl, v = t_ctrl[order], f[sig][order]
        i = np.searchsorted(t_ctrl, ch.result.t_s, side="right") - 1
        return np.where(i >= 0, v[np.clip(i, 0, None)], 0.0)

    def _runs(self, kind: str, t: np.ndarray, codes: np.ndarray) -> None:
        c = np.nan_to_num(np.asarray(codes, float), nan=0.0).astype(np.int64)
        code, t0 = self.open[kind]
        for j in np.flatnonzero(np.diff(np.concatenate(([code], c)))):
            if code:
                self.done[kind].append(Interval(t0, float(t[j]), kind, self.names[kind].get(code, str(code))))
            code, t0 = int(c[j]), float(t[j])
        self.open[kind] = (code, t0)

    def result(self) -> list[Interval]:
        out: list[Interval] = []
        for kind in ("FAULT", "fallback"):
            code, t0 = self.open[kind]
            if code:
                self.done[kind].append(Interval(t0, self.t_end, kind, self.names[kind].get(code, str(code))))
            out += sorted(self.done[kind], key=lambda iv: iv.t0_s)
        return sorted(out, key=lambda iv: iv.t0_s)


class _Counters:
    """The counters a log gives regardless of ground truth (:func:`~.logmetrics.log_metrics`'s
    ``extra``), summed over the chunks; each frame counted once (by its place in the file)."""

    def __init__(self) -> None:
        self.seen: dict[str, float] = {}
        self.last: dict[str, int] = {}
        self.span: dict[str, int] = {}
        self.cycle_max = -np.inf
        self.truth_in_rows = 0
        self.t_first: float | None = None

    def _new(self, ch: ChunkRows, name: str) -> dict[str, np.ndarray] | None:
        f = ch.frames.get(name)
        if f is None or not len(f["t_s"]):
            return None
        m = f[FRAME_INDEX] > self.seen.get(name, -1.0)
        self.seen[name] = max(self.seen.get(name, -1.0), float(np.max(f[FRAME_INDEX])))
        order = np.argsort(f["t_s"][m], kind="stable")
        return {k: v[m][order] for k, v in f.items()} if np.any(m) else None

    def _count(self, key: str, v: np.ndarray, modulo: int) -> None:
        raw = v.astype(np.int64)
        prev = self.last.get(key, int(raw[0]))
        self.span[key] = self.span.get(key, 0) + int(
            np.sum(np.mod(np.diff(np.concatenate(([prev], raw))), modulo))
        )
        self.last[key] = int(raw[-1])

    def add(self, ch: ChunkRows) -> None:
        if self.t_first is None:
            self.t_first = float(ch.t_rows[0])
        st, stats, truth = (self._new(ch, n) for n in ("CTRL_STATUS", "CTRL_STATS", "PLANT_TRUTH"))
        if st is not None:
            self._count("switches_counter", st["Switches"], 256)
        if stats is not None:
            self._count("overruns", stats["Overruns"], 65536)
            self.cycle_max = max(self.cycle_max, float(np.nanmax(stats["CycleTimeMax"])))
        if truth is not None:
            self.truth_in_rows += int(np.count_nonzero(truth["t_s"] >= self.t_first))

    def extra(self) -> dict[str, Any]:
        out: dict[str, Any] = dict(self.span)
        if "overruns" in out:
            out["cycle_time_max_s"] = self.cycle_max
        return out


class _Sums:
    """Everything summed over the chunks besides the scratch file: the figures' view, the
    intervals, the counters, the events seen on the bus and the injections."""

    def __init__(self, codec: FrameCodec) -> None:
        self.dec, self.intervals, self.counters = MinMaxDecimator(), _Intervals(codec), _Counters()
        self.bus_events: list[float] = []
        self.injections: list[tuple[float, str]] = []
        self.last: SimResult | None = None

    def add(self, ch: ChunkRows) -> None:
        r = self.last = ch.result
        self.dec.add({**r.arrays(), "stuck": r.stuck, "commanded_a": ch.commanded_a})
        self.intervals.add(ch)
        self.counters.add(ch)
        self.bus_events += r.event_times_s
        self.injections += ch.injections


def stream_log_run(
    path: str | os.PathLike[str],
    scenario: Scenario | None = None,
    params: Params | None = None,
    codec: FrameCodec | None = None,
    chunk_samples: int = CHUNK_SAMPLES,
) -> StreamedRun:
    """A log of any length (file or directory) read once, in chunks: metrics of every sample,
    the thinned samples for the figures (module docstring)."""
    log = resolve_log(path)
    side = read_sidecar(log)
    codec = codec if codec is not None else FrameCodec(_dbc_of(side))
    bad = BadLines()
    info = run_info(side, log.parent, scenario, log)
    prm = params if params is not None else load_params(info.params_path)
    stream = LogStream(log, codec, info, prm, bad, chunk_samples)
    with tempfile.TemporaryDirectory(prefix="ehpss-report-") as tmp:
        spill = Spill(Path(tmp))
        sums = _Sums(codec)
        for ch in stream.chunks():
            spill.add(ch.result)
            sums.add(ch)
            del ch
            release_freed_memory()
        dec, ivs, cnt, last = sums.dec, sums.intervals, sums.counters, sums.last
        bus_events, injections = sums.bus_events, sums.injections
        verdicts = {n: {v.name: c for v, c in per.items() if c} for n, per in codec.counts_by_name.items()}
        notes = ([bad.text()] if bad.count else []) + _notes(
            stream.state, info.reference is not None, spill, cnt
        )
        if info.reference is not None and info.sources and info.sources[0] not in ("--scenario", "sidecar"):
            notes.insert(0, f"reference taken from {', '.join(info.sources)} beside the log")
        counts = stream.state.frame_counts
        names = {n: {"t_s": np.zeros(0)} for n in counts}
        empty = (
            ""
            if spill.n
            else _why_empty({n: {"t_s": np.zeros(min(c, 1))} for n, c in counts.items()}, verdicts, bad)
        )
        ts = stream.state.ts_s or 1e-3
        sc = info.scenario
        inj = tuple(injections)
        events = spill.event_times(tuple(bus_events), sc, inj, ts)
        labels = event_labels(spill.result(events, ts), sc.events if sc is not None else (), inj)
        has_ref, has_truth = info.reference is not None, spill.has_truth
        who = (sc.name if sc is not None else "log", last.controller) if last is not None else None
        m = spill_metrics(spill, events, ts, has_truth, has_ref, who, cnt.extra(), verdicts)
    thin = _thinned(dec, last, sc, ts, events, has_truth)
    run = LogRun(
        log, thin, side, has_truth, has_ref, sc, dec_commanded(dec), names, verdicts, notes, empty, inj
    )
    counted = np.isfinite(thin.x_true_m) if has_truth else np.zeros(0, bool)
    view = RunView(thin, thin.controller, labels, ivs.result() if spill.n else [], counted)
    return StreamedRun(run, m, view, counts)


def dec_commanded(dec: MinMaxDecimator) -> np.ndarray:
    """The thinned commanded current (A)."""
    return dec.rows()["commanded_a"]


def _thinned(
    dec: MinMaxDecimator,
    last: SimResult | None,
    sc: Scenario | None,
    ts: float,
    events: tuple[float, ...],
    truth: bool,
) -> SimResult:
    rows = dec.rows()
    as_int = {k: np.nan_to_num(rows[k], nan=-1).astype(np.int64) for k in ("active_spool", "active_position")}
    return SimResult(
        scenario=sc.name if sc is not None else "log",
        controller=last.controller if last is not None else "unknown",
        ts_s=ts,
        event_times_s=events,
        t_s=rows["t_s"],
        x_d_m=rows["x_d_m"],
        y_m_m=rows["y_m_m"],
        x_true_m=rows["x_true_m"],
        y_s_m=rows["y_s_m"],
        spool_m=rows["spool_m"],
        current_a=rows["current_a"],
        active_spool=as_int["active_spool"],
        active_position=as_int["active_position"],
        k_loe_hat=rows["k_loe_hat"],
        k_dft_hat=rows["k_dft_hat"],
        index=rows["index"].reshape(-1, 16) if len(rows["index"]) else np.zeros((0, 16)),
        true_k_loe=rows["true_k_loe"],
        true_k_q=rows["true_k_q"],
        true_k_dft=rows["true_k_dft"],
        fresh=rows["fresh"] > 0.5,
        stuck=rows["stuck"] > 0.5 if truth else np.zeros(0, bool),
    )


def _notes(st: StreamState, has_ref: bool, spill: Spill, cnt: _Counters) -> list[str]:
    """The whole log's notes (:mod:`.logdata`'s words) from what the chunks counted."""
    notes = list(st.notes)
    if st.had_commands and not st.enabled:
        notes.append("no VALVE_CMD with Enable=1: the controller never went ACTIVE")
    if st.missing_commands:
        notes.append(
            f"{st.missing_commands} VALVE_CMD frames missing from the log (periods skipped by "
            "controller overruns, frames lost or not logged): their samples use the neighbours' timing"
        )
    if st.dropped_after_truth:
        notes.append(
            f"{st.dropped_after_truth} controller cycles after the emulator's last PLANT_TRUTH frame "
            "(the emulator had stopped) are left out"
        )
    if not has_ref:
        notes.append(
            "no reference in the metadata (sidecar scenario/config): x_d and y_m "
            "unavailable; pass --scenario to recompute them"
        )
    n = spill.n
    if spill.has_truth and n > 100 and abs(cnt.truth_in_rows - n) > 0.01 * n:
        notes.append(
            f"the controller ran {n} cycles while the emulator sent {cnt.truth_in_rows} PLANT_TRUTH "
            "frames in the same time: real time was not kept (overruns?); metrics are on the "
            "controller's time base"
        )
    if not spill.has_truth:
        notes.append(
            "no PLANT_TRUTH frames (emulator truth off): no ground truth, so no "
            "tracking-error metrics (RMS, peaks, recovery); sensor-based plots, "
            "model switches, k̂ and J are still shown"
        )
    return notes
