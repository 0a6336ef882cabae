"""What a report writes on its figures: each fault event in words ("LOE 50 %", "drift 0.8",
"sensor failed"), the intervals the controller spent in FAULT or on its nominal fallback with
their reasons, and the samples the metrics did not count. Pure: arrays in, labels out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .result import SimResult

#: a gain change smaller than this is no event (the DBC's PLANT_FAULTS LSB is 1e-4)
GAIN_STEP = 5e-5


@dataclass(frozen=True)
class Interval:
    """``[t0_s, t1_s)`` (s) of one run spent in ``kind`` ("FAULT" or "fallback") for ``reason``."""

    t0_s: float
    t1_s: float
    kind: str
    reason: str

    @property
    def label(self) -> str:
        """``FAULT: SENSOR_TIMEOUT``, ``fallback: PRODUCT_MISMATCH``."""
        return f"{self.kind}: {self.reason}" if self.reason else self.kind


def _num(v: float) -> str:
    return f"{v:.3g}"


def describe_changes(changes: dict[str, Any]) -> str:
    """A fault change in an engineer's words: ``{"k_loe": 0.5}`` → ``"LOE 50 %"``, ``k_dft``
    0.8 → ``"drift 0.8"``, 0 → ``"sensor failed"``, ``stuck`` → ``"sensor stuck"``, …; several
    changes joined by ``" + "``; a gain back to 1 says so (``"LOE cleared"``)."""
    parts = []
    for key, v in changes.items():
        if v is None:
            continue
        if key == "k_loe":
            parts.append("LOE cleared" if v == 1.0 else f"LOE {round((1.0 - float(v)) * 100):d} %")
        elif key == "k_q":
            parts.append("k_Q back to 1" if v == 1.0 else f"k_Q {_num(v)}")
        elif key == "k_dft":
            parts.append(
                "sensor failed" if v == 0.0 else ("drift cleared" if v == 1.0 else f"drift {_num(v)}")
            )
        elif key == "stuck":
            parts.append("sensor stuck" if v else "sensor unstuck")
        elif key == "position_bias_m":
            parts.append(f"sensor bias {float(v) * 1e3:.3g} mm")
        elif key == "current_limit_a":
            parts.append(f"current limit {float(v) * 1e3:.3g} mA")
        elif key.endswith("frame_loss"):
            who = key.removesuffix("frame_loss").rstrip("_") or "frame"
            parts.append(f"{who} loss {float(v) * 100:.3g} %")
    return " + ".join(parts) or "fault change"


def event_labels(r: SimResult, events: tuple[Any, ...] = ()) -> list[tuple[float, str]]:
    """``(t, words)`` for each event of ``r``: from the scenario's events when given (their
    fields as set), else from the true gains' change at that time (PLANT_FAULTS)."""
    if events:
        # the times the run saw (a log: PLANT_FAULTS on the controller's time) when they pair up
        times = r.event_times_s if len(r.event_times_s) == len(events) else tuple(e.t_s for e in events)
        out = []
        for t, ev in zip(times, events, strict=True):
            fields = {k: v for k, v in vars(ev).items() if k != "t_s" and v is not None}
            out.append((float(t), describe_changes(fields)))
        return out
    labels = []
    n = len(r.t_s)
    for t in r.event_times_s:
        k = min(round(t / r.ts_s), n - 1) if n else 0
        changes: dict[str, Any] = {}
        for key, arr in (("k_loe", r.true_k_loe), ("k_q", r.true_k_q), ("k_dft", r.true_k_dft)):
            if n and 0 < k < n and math.isfinite(arr[k]) and math.isfinite(arr[k - 1]):
                if (
                    abs(arr[k] - arr[k - 1]) > GAIN_STEP
                    or abs(arr[min(k + 1, n - 1)] - arr[k - 1]) > GAIN_STEP
                ):
                    changes[key] = round(float(arr[min(k + 1, n - 1)]), 4)
        labels.append((float(t), describe_changes(changes)))
    return labels


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(i0, i1), …]``: the half-open index ranges where ``mask`` is True."""
    m = np.asarray(mask, bool)
    if not m.any():
        return []
    d = np.diff(np.concatenate(([0], m.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def intervals(t_s: np.ndarray, codes: np.ndarray, kind: str, names: dict[int, str]) -> list[Interval]:
    """The intervals where ``codes`` (per sample; 0 or NaN: none) is non-zero, one per run of
    equal codes, named by ``names``; each ends one sample after its last (``t`` of the next)."""
    c = np.nan_to_num(np.asarray(codes, float), nan=0.0).astype(np.int64)
    out = []
    ts = float(t_s[1] - t_s[0]) if len(t_s) > 1 else 0.0
    for code in sorted(set(c[c != 0].tolist())):
        for i0, i1 in runs_of(c == code):
            t1 = float(t_s[i1]) if i1 < len(t_s) else float(t_s[-1]) + ts
            out.append(Interval(float(t_s[i0]), t1, kind, names.get(code, str(code))))
    return sorted(out, key=lambda iv: iv.t0_s)


def fallback_intervals(r: SimResult) -> list[Interval]:
    """The nominal-fallback intervals of a result that records them (no reason: the lockstep
    result keeps only the flag)."""
    fb = r.fallback
    if len(fb) != len(r.t_s) or not fb.any():
        return []
    return intervals(r.t_s, fb.astype(float), "fallback", {1: ""})
