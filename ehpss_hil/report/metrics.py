"""The docs/design.md §10 metrics — the one implementation used by ``sim``, ``bench`` and the tests.

``e = x_true − y_m`` at every sample (m).

* ``rms_error_m``: RMS of e over the whole run; ``pre_fault_max_m``: max |e| before the first event
  (the whole run when there is none).
* per fault event at ``t_s``: ``peak_error_m`` = max |e| in [t_s, t_s + 0.3 s);
  ``recovery_s`` = time after onset until |e| stays below 20 µm up to the next event (or the end
  of the run): 0 when it never leaves the band, ``inf`` when it is still outside at the end of the
  window; ``active_model`` = the active model slots at the last sample of the window
  (``{"spool": s, "position": p}`` for ``mmac``, ``{"joint": s}`` for ``mmac-paper``/``smac``,
  ``None`` for controllers without a bank); ``switches`` = model switches inside the window.
* ``switches``: total model switches (both channels; a joint bank counts once).

JSON: :meth:`RunMetrics.to_json` writes ``recovery_s = inf`` as ``null`` (JSON has no infinity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .result import SimResult

#: recovery band (m): 2 % of the 1 mm reference
RECOVERY_BAND_M = 20e-6
#: peak window after an event (s)
PEAK_WINDOW_S = 0.3
#: "do no harm" (docs/design.md §11): mmac RMS ≤ NO_HARM_RATIO·nrc RMS + NO_HARM_RMS_M (m);
#: a campaign run beyond it counts as harm
NO_HARM_RATIO = 1.1
NO_HARM_RMS_M = 1e-6
#: … and, where a run's worst error is judged too (bench, tests), mmac's worst |x − y_m| ≤
#: nrc's + NO_HARM_PEAK_M (m)
NO_HARM_PEAK_M = 10e-6
#: a fault counts as compensated when mmac RMS ≤ oracle RMS + COMPENSATED_RMS_M (m)
COMPENSATED_RMS_M = 5e-6


@dataclass
class EventMetrics:
    """Metrics of one fault event (SI)."""

    t_s: float
    peak_error_m: float
    recovery_s: float
    active_model: dict[str, int] | None
    switches: int = 0

    def to_json(self) -> dict[str, Any]:
        """docs/design.md §10 event row (inf → null)."""
        return {
            "t_s": self.t_s,
            "peak_error_m": self.peak_error_m,
            "recovery_s": None if math.isinf(self.recovery_s) else self.recovery_s,
            "active_model": self.active_model,
        }


@dataclass
class RunMetrics:
    """Metrics of one (scenario, controller) run."""

    scenario: str
    controller: str
    rms_error_m: float
    pre_fault_max_m: float
    switches: int
    events: list[EventMetrics] = field(default_factory=list)
    #: simulated seconds per wall second of the run's loop (0: not timed); not part of the JSON
    speed: float = 0.0
    #: simulated duration (s)
    duration_s: float = 0.0
    #: worst |x − y_m| over the whole run (m); not part of the JSON row
    max_error_m: float = 0.0
    #: time the do-no-harm monitor held the loop on nominal compensation (s); not in the JSON
    fallback_s: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """The docs/design.md §10 JSON row."""
        return {
            "scenario": self.scenario,
            "controller": self.controller,
            "rms_error_m": self.rms_error_m,
            "pre_fault_max_m": self.pre_fault_max_m,
            "switches": self.switches,
            "events": [e.to_json() for e in self.events],
        }


def harm_rms_limit_m(nrc_rms_m: float) -> float:
    """The RMS (m) mmac may reach without doing harm where the plain loop reached ``nrc_rms_m``
    (the campaigns judge this alone)."""
    return NO_HARM_RATIO * nrc_rms_m + NO_HARM_RMS_M


def harm_limits(nrc: RunMetrics) -> tuple[float, float]:
    """The RMS and worst |x − y_m| (m) mmac may reach without doing harm on the run where the
    plain loop reached ``nrc``'s."""
    return harm_rms_limit_m(nrc.rms_error_m), nrc.max_error_m + NO_HARM_PEAK_M


def does_harm(mmac: RunMetrics, nrc: RunMetrics) -> bool:
    """mmac's RMS or worst error beyond :func:`harm_limits` of the plain loop's on the same run."""
    lim, plim = harm_limits(nrc)
    return mmac.rms_error_m > lim or mmac.max_error_m > plim


def _changes(a: np.ndarray) -> np.ndarray:
    """Boolean per sample: the slot changed at this sample (first sample: False)."""
    out = np.zeros(len(a), dtype=bool)
    out[1:] = a[1:] != a[:-1]
    return out


def _switch_marks(r: SimResult) -> np.ndarray:
    sp = _changes(r.active_spool)
    if np.array_equal(r.active_spool, r.active_position):
        return sp
    return sp | _changes(r.active_position)


def _active(r: SimResult, i: int) -> dict[str, int] | None:
    sp, ps = int(r.active_spool[i]), int(r.active_position[i])
    if sp < 0 and ps < 0:
        return None
    if sp == ps:
        return {"joint": sp}
    return {"spool": sp, "position": ps}


def recovery_time_s(abs_err: np.ndarray, ts_s: float, band_m: float = RECOVERY_BAND_M) -> float:
    """Time from the window start until |e| stays below ``band_m`` to the window end (s)."""
    out = np.flatnonzero(abs_err >= band_m)
    if len(out) == 0:
        return 0.0
    if out[-1] == len(abs_err) - 1:
        return math.inf
    return float((out[-1] + 1) * ts_s)


def compute_metrics(r: SimResult) -> RunMetrics:
    """All docs/design.md §10 metrics of one run."""
    e = np.abs(r.error_m)
    n, ts = len(e), r.ts_s
    starts = [min(round(t / ts), n) for t in r.event_times_s]
    first = starts[0] if starts else n
    marks = _switch_marks(r)
    events = []
    for i, k0 in enumerate(starts):
        k1 = starts[i + 1] if i + 1 < len(starts) else n
        if k1 <= k0:
            continue
        kp = min(k0 + round(PEAK_WINDOW_S / ts), n)
        events.append(
            EventMetrics(
                t_s=r.event_times_s[i],
                peak_error_m=float(e[k0:kp].max()),
                recovery_s=recovery_time_s(e[k0:k1], ts),
                active_model=_active(r, k1 - 1),
                switches=int(np.count_nonzero(marks[k0:k1])),
            )
        )
    return RunMetrics(
        scenario=r.scenario,
        controller=r.controller,
        rms_error_m=float(np.sqrt(np.mean(r.error_m**2))),
        pre_fault_max_m=float(e[:first].max()) if first > 0 else 0.0,
        switches=int(np.count_nonzero(marks)),
        events=events,
        speed=r.speed,
        duration_s=r.duration_s,
        max_error_m=float(e.max()) if n else 0.0,
        fallback_s=float(np.count_nonzero(r.fallback)) * ts,
    )
