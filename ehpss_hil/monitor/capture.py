"""Triggered capture for the monitor: ``before_s`` seconds before and ``after_s`` after a trigger
saved as a candump ``-L`` log of every frame received (what ``report``/``replay`` read) and a
CSV of the monitor's rows (SI units, the run-time column first).

Triggers, judged on each new row: ``event`` — a fault event (a true gain or the stuck flag
changed), the controller entering FAULT or its nominal fallback; ``threshold`` — ``|field|``
above ``level`` (SI, e.g. ``e_m`` 50e-6). Frames are kept (as ``(t, id, data)`` tuples, not
python-can messages) only while a capture is armed, and only for the span it needs, so an
unarmed monitor pays nothing. Pure apart from :meth:`Capture.write` (the two files).
"""

from __future__ import annotations

import csv
import math
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import can

from ..errors import CaptureError
from .state import ROW_FIELDS, STATE_FAULT

#: longest span before / after a trigger (s): at about 6000 frames/s, 10 s is ~60 000 frames
MAX_SPAN_S = 10.0
#: the row fields whose change is a fault event
EVENT_FIELDS = ("k_loe_true", "k_dft_true", "k_q_true", "stuck")
#: the row fields a threshold may watch
THRESHOLD_FIELDS = ("e_m", "x_true_m", "y_s_m", "i_cmd_a", "i_applied_a", "k_loe_hat", "k_dft_hat")
#: a gain change smaller than this is no event (PLANT_FAULTS LSB 1e-4)
EVENT_STEP = 5e-5
#: the candump channel name written in captured logs
CHANNEL = "can0"


@dataclass(frozen=True)
class CaptureSpec:
    """What to capture: ``trigger`` ``event`` or ``threshold`` (``|field| > level``, SI), and
    the span ``before_s`` / ``after_s`` (s) around the trigger."""

    trigger: str = "event"
    before_s: float = 2.0
    after_s: float = 2.0
    field: str = "e_m"
    level: float = 0.0

    def __post_init__(self) -> None:
        if self.trigger not in ("event", "threshold"):
            raise CaptureError(f"capture trigger must be event or threshold, got {self.trigger!r}")
        for name, v in (("before_s", self.before_s), ("after_s", self.after_s)):
            if not (math.isfinite(v) and 0.0 <= v <= MAX_SPAN_S):
                raise CaptureError(f"capture {name} must be 0 … {MAX_SPAN_S:g} s, got {v!r}")
        if self.trigger == "threshold":
            if self.field not in THRESHOLD_FIELDS:
                raise CaptureError(f"capture field must be one of {', '.join(THRESHOLD_FIELDS)}")
            if not (math.isfinite(self.level) and self.level >= 0.0):
                raise CaptureError(f"capture level must be a finite number ≥ 0, got {self.level!r}")


def _changed(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return False  # first heard: not a change
    return abs(a - b) > EVENT_STEP


class Capture:
    """One armed capture (see the module docstring); ``out_dir``: where the files go, ``n``
    its number in their names."""

    def __init__(self, spec: CaptureSpec, out_dir: Path, n: int) -> None:
        self.spec = spec
        self.out_dir = out_dir
        self.n = n
        self.frames: deque[tuple[float, int, bytes, bool]] = deque()
        self.fired_t_s = math.nan
        self.reason = ""
        self.files: list[str] = []
        self._prev: dict[str, float] = {}

    @property
    def state(self) -> str:
        """``armed``, ``triggered`` (collecting the after span) or ``saved``."""
        return "saved" if self.files else ("triggered" if math.isfinite(self.fired_t_s) else "armed")

    def frame(self, msg: can.Message, t: float) -> None:
        """Keep one frame received at ``t`` (s, epoch: the rows' clock) while it may be needed."""
        if self.files:
            return
        self.frames.append((t, msg.arbitration_id, bytes(msg.data), msg.is_extended_id))
        if math.isnan(self.fired_t_s):  # armed: only the before span is needed
            while self.frames and self.frames[0][0] < t - self.spec.before_s:
                self.frames.popleft()

    def row(self, values: dict[str, float]) -> bool:
        """Judge one new row (``ROW_FIELDS`` → SI value); True when the capture is complete and
        should be written now."""
        if self.files:
            return False
        t = values["t_s"]
        if math.isnan(self.fired_t_s):
            why = self._trigger(values)
            if why:
                self.fired_t_s, self.reason = t, why
        self._prev = dict(values)
        return math.isfinite(self.fired_t_s) and t >= self.fired_t_s + self.spec.after_s

    def _trigger(self, v: dict[str, float]) -> str:
        sp, p = self.spec, self._prev
        if sp.trigger == "threshold":
            x = v.get(sp.field, math.nan)
            return f"|{sp.field}| > {sp.level:g}" if math.isfinite(x) and abs(x) > sp.level else ""
        if not p:
            return ""
        for f in EVENT_FIELDS:
            if _changed(v[f], p[f]):
                return f"{f} {p[f]:g} → {v[f]:g}"
        if v["state"] == STATE_FAULT and p["state"] != STATE_FAULT:
            return "fail-safe (FAULT)"
        if v["fallback"] == 1.0 and p["fallback"] != 1.0:
            return "nominal fallback"
        return ""

    def write(self, rows: list[tuple[float, ...]], t0_s: float) -> list[Path]:
        """Write ``capture-N.log`` (candump -L) and ``capture-N.csv`` (the ``rows`` in the span;
        ``t_run_s`` = receive time − ``t0_s``, the page's run time) into ``out_dir``."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        stem = (
            self.out_dir
            / f"capture-{self.n:03d}-{time.strftime('%Y%m%dT%H%M%S', time.gmtime(self.fired_t_s))}"
        )
        lo, hi = self.fired_t_s - self.spec.before_s, self.fired_t_s + self.spec.after_s
        log, table = stem.with_suffix(".log"), stem.with_suffix(".csv")
        with log.open("w", encoding="ascii") as f:
            for t, can_id, data, ext in self.frames:
                if lo <= t <= hi:
                    cid = f"{can_id:08X}" if ext else f"{can_id:03X}"
                    f.write(f"({t:.6f}) {CHANNEL} {cid}#{data.hex().upper()}\n")
        with table.open("w", encoding="ascii", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t_run_s", *ROW_FIELDS])
            for r in rows:
                if lo <= r[0] <= hi:
                    w.writerow([f"{r[0] - t0_s:.6f}", *(_cell(x) for x in r)])
        self.frames.clear()
        self.files = [log.name, table.name]
        return [log, table]

    def summary(self, t0_s: float) -> dict[str, object]:
        """JSON-ready: state, trigger, the trigger time on the run's axis (s), reason, files."""
        fired = self.fired_t_s - t0_s if math.isfinite(self.fired_t_s) and math.isfinite(t0_s) else None
        return {
            "n": self.n,
            "state": self.state,
            "trigger": self.spec.trigger,
            "before_s": self.spec.before_s,
            "after_s": self.spec.after_s,
            "fired_run_s": fired,
            "reason": self.reason,
            "files": list(self.files),
        }


def _cell(x: float) -> str:
    return "" if math.isnan(x) else repr(float(x))
