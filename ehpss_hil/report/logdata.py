"""A CAN log (any format :func:`~ehpss_hil.canlog.read_frames` reads) turned into the
per-sample record a report needs (a :class:`SimResult`; its metrics: :mod:`.logmetrics`).

Alignment (the controller's view, one row per logged VALVE_CMD):

- the controller's sample index is ``k = CycleCount − CycleCount₀`` (16-bit counter unwrapped;
  ``CycleCount₀`` = the first command with ``Enable = 1``: the controller daemon starts its
  reference at its first ACTIVE cycle), ``t = k·Ts``;
- every other signal is the newest frame logged **before** that command (zero-order hold on the
  log's timestamps): x_true from PLANT_TRUTH, y_s/spool from SENSOR_POS (``fresh`` when one
  arrived since the previous command), applied current over [k, k+1) from the SENSOR_AUX echo
  of sample k+1 (the commanded one is :attr:`LogRun.commanded_current_a`), active models and k̂
  from CTRL_STATUS, J per slot from CTRL_INDEX, true gains from PLANT_FAULTS;
- the timestamps are the host's wall clock: a clock step in the middle of a realtime run (NTP,
  ``date``) is found where the wall clock disagrees with the CycleCount and undone before frames
  are paired (:mod:`.logclock`), and noted; a pause in a lockstep run is just a pause;
- x_d and y_m (ReferenceModel, exact ZOH, from rest at k = 0) come from the run's reference: the
  sidecar's ``scenario`` (a mapping, a YAML path, or a scenario name found in ``scenarios/``),
  or ``config.reference``/``reference`` with ``config.rate_hz``/``rate_hz``, or the caller's.

A log without VALVE_CMD falls back to one row per PLANT_TRUTH frame (k counted from the first);
without PLANT_TRUTH the tracking-error metrics are unavailable and :attr:`LogRun.notes` says so.
A log that gives no sample at all says why in :attr:`LogRun.no_samples` (``report`` makes that
one line and exit 2).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..canlog import BadLines, decode_log, read_sidecar
from ..canlog.reader import FRAME_INDEX, resolve_log
from ..codec import FrameCodec
from ..physics.load import load_params
from ..physics.params import Params
from ..physics.reference import ReferenceModel
from ..runtime.status_frames import MODE_CODE
from ..scenario import Scenario
from .annotate import bus_event_times, event_labels, injection_events
from .logbounds import check_sample_time, check_span
from .logclock import undo_clock_steps, unwrap_counter
from .logmeta import RunInfo, reference_of, run_info
from .result import N_SLOTS, SimResult

__all__ = ["LogRun", "load_log_run", "reference_of"]

MODE_NAMES = {code: mode for mode, code in MODE_CODE.items()}  # CTRL_STATUS Mode → mode
_NO_MODEL = 15  # CTRL_STATUS nibble of "no bank" (−1 & 0xF)
#: frames a :class:`LogRun` keeps whole for the views (status intervals, counters); the others
#: keep their timestamps only once laid out per sample
_VIEWED = frozenset({"VALVE_CMD", "CTRL_STATUS", "CTRL_STATS", "PLANT_FAULTS"})


@dataclass
class LogRun:
    """A decoded log: ``result`` (per-sample arrays, SI) plus what the log could not give."""

    log_path: Path
    result: SimResult
    sidecar: dict[str, Any] | None
    has_truth: bool
    has_reference: bool
    scenario: Scenario | None
    commanded_current_a: np.ndarray
    #: decoded frames by name: whole for :data:`_VIEWED`, the others their ``t_s`` only
    frames: dict[str, dict[str, np.ndarray]]
    verdicts: dict[str, dict[str, int]]
    notes: list[str] = field(default_factory=list)
    #: why the log gave no sample row (empty when it gave some)
    no_samples: str = ""
    #: ``(t, words)`` of applied injections only FAULT_INJECT_ACK shows (a frame loss, a bias)
    injections: tuple[tuple[float, str], ...] = ()


# ---- helpers on decoded arrays ----------------------------------------------------------------
def hold(
    t_src: np.ndarray, v_src: np.ndarray, t_query: np.ndarray, default: float | None = np.nan
) -> np.ndarray:
    """Zero-order hold: the newest ``v_src`` at or before each ``t_query``; before the first
    source sample ``default`` (None: the first source value, i.e. backfill)."""
    if len(t_src) == 0:
        return np.full(len(t_query), np.nan if default is None else default)
    i = np.searchsorted(t_src, t_query, side="right") - 1
    fill = v_src[0] if default is None else default
    out = np.where(i >= 0, v_src[np.clip(i, 0, None)], fill)
    return out.astype(float)


def _sorted(frames: dict[str, dict[str, np.ndarray]], name: str) -> dict[str, np.ndarray]:
    f = frames.get(name)
    if not f:
        return {"t_s": np.zeros(0)}
    order = np.argsort(f["t_s"], kind="stable")
    return {k: v[order] for k, v in f.items()}


def _rows(
    log: Path, frames: dict[str, dict[str, np.ndarray]], notes: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(k, wall time (s), commanded current (A))`` of every sample 0…K (module docstring).

    Samples whose VALVE_CMD is missing from the log get an interpolated wall time and a NaN
    commanded current, so the arrays stay on the uniform grid the metrics expect.
    """
    cmd = frames.get("VALVE_CMD")
    if cmd is not None and len(cmd["t_s"]):
        cyc = unwrap_counter(cmd["CycleCount"])
        enabled = np.flatnonzero(cmd["Enable"] > 0.5)
        if len(enabled) == 0:
            notes.append("no VALVE_CMD with Enable=1: the controller never went ACTIVE")
        start = int(enabled[0]) if len(enabled) else 0
        k = cyc[start:] - cyc[start]
        check_span(log, int(k[-1]) + 1, len(k), "VALVE_CMD")
        k_all = np.arange(int(k[-1]) + 1)
        missing = len(k_all) - len(np.unique(k))
        if missing:
            notes.append(
                f"{missing} VALVE_CMD frames missing from the log (periods skipped by "
                "controller overruns, frames lost or not logged): their samples use "
                "the neighbours' timing"
            )
        t_all = np.interp(k_all, k, cmd["t_s"][start:])
        i_all = np.full(len(k_all), np.nan)
        i_all[k] = cmd["CurrentSetpoint"][start:]
        return k_all, t_all, i_all
    truth = frames.get("PLANT_TRUTH")
    if truth is not None and len(truth["t_s"]):
        notes.append(
            "no VALVE_CMD in the log: one row per PLANT_TRUTH frame, the reference "
            "assumed to start at the first one"
        )
        n = len(truth["t_s"])
        check_span(log, n, n, "PLANT_TRUTH")
        return np.arange(n), truth["t_s"] + 1e-9, np.full(n, np.nan)
    return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)


def _within_truth(
    frames: dict[str, dict[str, np.ndarray]],
    k: np.ndarray,
    t_rows: np.ndarray,
    i_cmd: np.ndarray,
    ts_s: float,
    notes: list[str],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop the rows after the emulator's last PLANT_TRUTH frame (+ 1.5 periods): the plant was
    no longer emulated there (the run stops the emulator first, the controller then sees no data
    and goes to its fail-safe), so there is no ground truth to score them against."""
    truth = frames.get("PLANT_TRUTH")
    if truth is None or not len(truth["t_s"]) or not len(t_rows):
        return k, t_rows, i_cmd
    pos = frames.get("SENSOR_POS", {"t_s": np.zeros(0)})["t_s"]
    keep = rows_with_truth(t_rows, float(np.max(truth["t_s"])), pos, ts_s)
    n_drop = len(t_rows) - int(np.count_nonzero(keep))
    if n_drop:
        notes.append(
            f"{n_drop} controller cycles after the emulator's last PLANT_TRUTH frame "
            "(the emulator had stopped) are left out"
        )
    return k[keep], t_rows[keep], i_cmd[keep]


def rows_with_truth(
    t_rows: np.ndarray, last_truth_s: float, t_pos: np.ndarray, ts_s: float, t_before: float = -np.inf
) -> np.ndarray:
    """Which controller rows (times in s) have ground truth to be scored against: those up to
    1.5 periods after the emulator's last PLANT_TRUTH frame, and the first later row when a
    SENSOR_POS frame (times ``t_pos``) sent up to then arrived after the row before it — the
    answer to the last sample with truth, which a loaded host may send periods late (a lockstep
    run lost its last sample so, its command logged 5 ms after the truth frame). ``t_before``:
    the time of the row before ``t_rows[0]`` (a streamed chunk's predecessor)."""
    t_end = last_truth_s + 1.5 * ts_s
    keep = t_rows <= t_end
    beyond = np.flatnonzero(~keep)
    if len(beyond):
        i = int(beyond[0])
        prev = float(t_rows[i - 1]) if i else t_before
        if np.any((t_pos > prev) & (t_pos <= t_end)):
            keep[i] = True
    return keep


def _fresh(t_pos: np.ndarray, t_rows: np.ndarray) -> np.ndarray:
    """True where a SENSOR_POS frame arrived after the previous row and up to this one."""
    n_upto = np.searchsorted(t_pos, t_rows, side="right")
    prev = np.concatenate(([0], n_upto[:-1]))
    return n_upto > prev


def _index_matrix(idx: dict[str, np.ndarray], t_rows: np.ndarray) -> np.ndarray:
    out = np.full((len(t_rows), N_SLOTS), np.nan)
    if len(idx["t_s"]) == 0:
        return out
    for slot in range(N_SLOTS):
        col = idx.get(f"J_{slot}")
        if col is None:
            continue
        m = np.isfinite(col)
        out[:, slot] = hold(idx["t_s"][m], col[m], t_rows)
    return out


# ---- the whole log ----------------------------------------------------------------------------
def load_log_run(
    path: str | os.PathLike[str],
    scenario: Scenario | None = None,
    params: Params | None = None,
    codec: FrameCodec | None = None,
) -> LogRun:
    """Decode a log (file or directory, whole rotation set) into a :class:`LogRun`."""
    log = resolve_log(path)
    side = read_sidecar(log)
    codec = codec if codec is not None else FrameCodec(_dbc_of(side))
    bad = BadLines()
    frames = decode_log(log, codec, bad=bad, order=True)
    verdicts = {n: {v.name: c for v, c in per.items() if c} for n, per in codec.counts_by_name.items()}
    notes: list[str] = [bad.text()] if bad.count else []
    info = run_info(side, log.parent, scenario, log)
    notes += undo_clock_steps(frames, info.ts_s, info.lockstep)[1]
    for f in frames.values():
        f.pop(FRAME_INDEX, None)
    sc, ref, ts = info.scenario, info.reference, info.ts_s
    if ref is not None and info.sources and info.sources[0] not in ("--scenario", "sidecar"):
        notes.append(f"reference taken from {', '.join(info.sources)} beside the log")
    k, t_rows, i_cmd = _rows(log, frames, notes)
    if ts is None:
        ts = _median_period(t_rows) or 1e-3
        notes.append(f"sample time not in the metadata: {ts * 1e3:.4g} ms from the log's timing")
        check_sample_time(log, ts, "from the log's timing")
    else:
        check_sample_time(log, ts, "from the metadata")
    k, t_rows, i_cmd = _within_truth(frames, k, t_rows, i_cmd, ts, notes)
    empty = _why_empty(frames, verdicts, bad) if len(k) == 0 else ""
    prm = params if params is not None else load_params(info.params_path)
    x_d = np.full(len(k), np.nan)
    y_m = np.full(len(k), np.nan)
    if ref is not None and len(k):
        base = Path(sc.base_dir) if sc is not None and sc.base_dir else None
        xd_all = ref.sample(np.arange(int(k[-1]) + 1) * ts, base)
        x_d = xd_all[k]
        y_m = ReferenceModel(prm, ts).simulate(xd_all)[k]
    elif ref is None:
        notes.append(
            "no reference in the metadata (sidecar scenario/config): x_d and y_m "
            "unavailable; pass --scenario to recompute them"
        )
    result, has_truth = _assemble(frames, sc, info, k, t_rows, ts, x_d, y_m, notes)
    injections = tuple(injection_events(_sorted(frames, "FAULT_INJECT_ACK"), codec, t_rows, k, ts))
    if injections:  # events too: in the metrics' event table and on the figures
        result.event_times_s = tuple(sorted({*result.event_times_s, *(t for t, _ in injections)}))
    for name in set(frames) - _VIEWED:  # laid out per sample: only the count is still read
        frames[name] = {"t_s": frames[name]["t_s"]}
    has_ref = ref is not None
    return LogRun(
        log, result, side, has_truth, has_ref, sc, i_cmd, frames, verdicts, notes, empty, injections
    )


def _assemble(
    frames: dict[str, dict[str, np.ndarray]],
    sc: Scenario | None,
    info: RunInfo,
    k: np.ndarray,
    t_rows: np.ndarray,
    ts: float,
    x_d: np.ndarray,
    y_m: np.ndarray,
    notes: list[str],
) -> tuple[SimResult, bool]:
    pos, aux = _sorted(frames, "SENSOR_POS"), _sorted(frames, "SENSOR_AUX")
    truth, flt = _sorted(frames, "PLANT_TRUTH"), _sorted(frames, "PLANT_FAULTS")
    st, idx = _sorted(frames, "CTRL_STATUS"), _sorted(frames, "CTRL_INDEX")
    has_truth = len(truth["t_s"]) > 0
    if has_truth and len(t_rows) > 100:
        n_emu = int(np.count_nonzero((truth["t_s"] >= t_rows[0]) & (truth["t_s"] <= t_rows[-1])))
        if abs(n_emu - len(t_rows)) > 0.01 * len(t_rows):
            notes.append(
                f"the controller ran {len(t_rows)} cycles while the emulator sent "
                f"{n_emu} PLANT_TRUTH frames in the same time: real time was not kept "
                "(overruns?); metrics are on the controller's time base"
            )
    if not has_truth:
        notes.append(
            "no PLANT_TRUTH frames (emulator truth off): no ground truth, so no "
            "tracking-error metrics (RMS, peaks, recovery); sensor-based plots, "
            "model switches, k̂ and J are still shown"
        )

    def col(f: dict[str, np.ndarray], sig: str, default: float | None = np.nan) -> np.ndarray:
        if sig not in f:
            return np.full(len(k), np.nan if default is None else default)
        return hold(f["t_s"], f[sig], t_rows, default)

    # models before the first CTRL_STATUS: backfilled (a start-up value is not a switch)
    spool_m, pos_m = col(st, "ActiveSpoolModel", None), col(st, "ActivePosModel", None)
    spool_m[np.isnan(spool_m)] = _NO_MODEL
    pos_m[np.isnan(pos_m)] = _NO_MODEL
    applied = np.append(col(aux, "CoilCurrent")[1:], np.nan)  # echo at k+1 = over [k, k+1)
    events = bus_event_times(flt, truth, t_rows, k, ts)
    mode = _mode(st, info)
    res = SimResult(
        scenario=sc.name if sc is not None else "log",
        controller=mode,
        ts_s=ts,
        event_times_s=events,
        t_s=k * ts,
        x_d_m=x_d,
        y_m_m=y_m,
        x_true_m=col(truth, "Position"),
        y_s_m=col(pos, "Position"),
        spool_m=col(pos, "Spool"),
        current_a=applied,
        active_spool=np.where(spool_m == _NO_MODEL, -1, spool_m).astype(np.int64),
        active_position=np.where(pos_m == _NO_MODEL, -1, pos_m).astype(np.int64),
        k_loe_hat=col(st, "KLoeHat"),
        k_dft_hat=col(st, "KDftHat"),
        index=_index_matrix(idx, t_rows),
        true_k_loe=col(flt, "KLoe"),
        true_k_q=col(flt, "KQ"),
        true_k_dft=col(flt, "KDft"),
        fresh=_fresh(pos["t_s"], t_rows) if len(pos["t_s"]) else np.zeros(len(k), bool),
        stuck=col(truth, "Stuck", 0.0) > 0.5 if has_truth else np.zeros(0, bool),
    )
    if sc is not None:  # every scenario event, also those the bus cannot show (a bias, a loss)
        res.event_times_s = tuple(t for t, _ in event_labels(res, sc.events))
    return res, has_truth


def _why_empty(
    frames: dict[str, dict[str, np.ndarray]], verdicts: dict[str, dict[str, int]], bad: BadLines
) -> str:
    """Why a log gave no sample row, in a few words (for the one-line error)."""
    if not verdicts:
        lines = f" ({bad.text()})" if bad.count else ""
        return f"no frame of the DBC could be read from it{lines}"
    rows = [n for n in ("VALVE_CMD", "PLANT_TRUTH") if len(frames.get(n, {}).get("t_s", ()))]
    if rows:
        return "every controller cycle lies after the emulator's last PLANT_TRUTH frame"
    seen = ", ".join(f"{n} {sum(c.values())}" for n, c in sorted(verdicts.items()))
    return f"no usable VALVE_CMD or PLANT_TRUTH frame (frames of the DBC: {seen})"


def _mode(st: dict[str, np.ndarray], info: RunInfo) -> str:
    if "Mode" in st and len(st["Mode"]):
        return MODE_NAMES.get(int(st["Mode"][-1]), "unknown")
    return info.mode or "unknown"


def _median_period(t: np.ndarray) -> float | None:
    if len(t) < 3:
        return None
    return float(np.round(np.median(np.diff(t)), 6)) or None


def _dbc_of(side: dict[str, Any] | None) -> str | None:
    dbc = (side or {}).get("dbc")
    p = dbc.get("path") if isinstance(dbc, dict) else dbc
    return str(p) if p and Path(str(p)).is_file() else None
