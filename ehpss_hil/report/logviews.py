"""A logged run as the figures draw it (:class:`~.figures.RunView`): events in words, the
intervals the controller spent in FAULT (CTRL_STATUS State 3, by FailsafeReason) or on its
nominal fallback (CTRL_STATUS NominalFallback, by CTRL_STATS FallbackReason), and the samples
its metrics counted.

Status frames are placed on the report's time axis (the controller's ``t = k·Ts``) through the
VALVE_CMD frames: a frame received at wall time ``w`` lies at the controller time of the
commands around it (linear between two commands), the alignment of :mod:`.logdata`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..codec import FrameCodec
from .annotate import Interval, event_labels, intervals
from .figures import RunView
from .logdata import LogRun, hold, unwrap_counter


def _names(codec: FrameCodec, frame: str, signal: str) -> dict[int, str]:
    choices: dict[int, Any] = codec.message(frame).get_signal_by_name(signal).choices or {}
    return {int(k): str(v) for k, v in choices.items()}


def controller_time(run: LogRun, t_wall: np.ndarray) -> np.ndarray | None:
    """The report's time (s, ``k·Ts``) of wall-clock receive times ``t_wall`` (None without
    enabled VALVE_CMD frames in the log)."""
    cmd = run.frames.get("VALVE_CMD")
    if cmd is None or not len(cmd["t_s"]):
        return None
    order = np.argsort(cmd["t_s"], kind="stable")
    t_cmd, enable = cmd["t_s"][order], cmd["Enable"][order]
    cyc = unwrap_counter(cmd["CycleCount"][order])
    on = np.flatnonzero(enable > 0.5)
    if len(on) == 0:
        return None
    start = int(on[0])
    k = (cyc[start:] - cyc[start]).astype(float)
    return np.interp(t_wall, t_cmd[start:], k * run.result.ts_s)


def status_intervals(run: LogRun, codec: FrameCodec | None = None) -> list[Interval]:
    """FAULT and fallback intervals of a logged run, with their reasons (see the module)."""
    st = run.frames.get("CTRL_STATUS")
    r = run.result
    if st is None or not len(st["t_s"]) or not len(r.t_s):
        return []
    t_st = controller_time(run, st["t_s"])
    if t_st is None:
        return []
    codec = codec if codec is not None else FrameCodec()
    order = np.argsort(t_st, kind="stable")
    t_st = t_st[order]
    state = hold(t_st, st["State"][order], r.t_s, 0.0)
    reason = hold(t_st, st["FailsafeReason"][order], r.t_s, 0.0)
    fail_names = {1 + k: v for k, v in _names(codec, "CTRL_STATUS", "FailsafeReason").items()}
    out = intervals(r.t_s, np.where(state == 3, 1 + reason, 0), "FAULT", fail_names)
    fb = hold(t_st, st["NominalFallback"][order], r.t_s, 0.0)
    stats = run.frames.get("CTRL_STATS")
    why = np.zeros(len(r.t_s))
    if stats is not None and len(stats["t_s"]):
        t_stats = controller_time(run, stats["t_s"])
        if t_stats is not None:
            o = np.argsort(t_stats, kind="stable")
            why = hold(t_stats[o], stats["FallbackReason"][o], r.t_s, 0.0)
    fb_names = {
        1 + k: ("" if k == 0 else v) for k, v in _names(codec, "CTRL_STATS", "FallbackReason").items()
    }
    out += intervals(r.t_s, np.where(fb > 0.5, 1 + why, 0), "fallback", fb_names)
    return sorted(out, key=lambda iv: iv.t0_s)


def counted_samples(run: LogRun) -> np.ndarray:
    """True for the samples whose ground truth is in the log: the metrics hold x over the others
    (``x_true_filled_samples``), so the figures draw those as gaps, not as measured tracking."""
    return np.isfinite(run.result.x_true_m) if run.has_truth else np.zeros(0, bool)


def log_view(run: LogRun, label: str = "") -> RunView:
    """The :class:`RunView` of a logged run."""
    events = run.scenario.events if run.scenario is not None else ()
    return RunView(
        run.result,
        label or run.result.controller,
        event_labels(run.result, events, run.injections),
        status_intervals(run),
        counted_samples(run),
    )
