"""What a report writes on its figures: each fault event in words ("LOE 50 %", "drift 0.8",
"sensor failed"), the intervals the controller spent in FAULT or on its nominal fallback with
their reasons, and the samples the metrics did not count. Pure: arrays in, labels out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .result import SimResult

if TYPE_CHECKING:
    from ..codec import FrameCodec

#: a gain change smaller than this is no event (the DBC's PLANT_FAULTS LSB is 1e-4)
GAIN_STEP = 5e-5
#: a time within this (s) of where a scenario event the bus cannot show is expected is that
#: event's (a second labelling of the same run finds the time the first one placed)
EVENT_MATCH_S = 0.1
#: the scenario fields a change on the bus shows (PLANT_FAULTS gains, PLANT_TRUTH Stuck)
BUS_VISIBLE = ("k_loe", "k_q", "k_dft", "stuck")


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


def _changes_at(r: SimResult, t: float) -> dict[str, Any]:
    """The true fault values that changed at ``t`` (s): gains (PLANT_FAULTS) and the stuck flag
    (PLANT_TRUTH Stuck), as a scenario event would set them."""
    n = len(r.t_s)
    k = min(round(t / r.ts_s), n - 1) if n else 0
    changes: dict[str, Any] = {}
    if not 0 < k < n:
        return changes
    after = min(k + 1, n - 1)
    for key, arr in (("k_loe", r.true_k_loe), ("k_q", r.true_k_q), ("k_dft", r.true_k_dft)):
        if math.isfinite(arr[k]) and math.isfinite(arr[k - 1]):
            if abs(arr[k] - arr[k - 1]) > GAIN_STEP or abs(arr[after] - arr[k - 1]) > GAIN_STEP:
                changes[key] = round(float(arr[after]), 4)
    st = r.stuck
    if len(st) == n and (st[k] != st[k - 1] or st[after] != st[k - 1]):
        changes["stuck"] = bool(st[after])
    return changes


def bus_event_times(
    faults: dict[str, np.ndarray], truth: dict[str, np.ndarray], t_rows: np.ndarray, k: np.ndarray, ts: float
) -> tuple[float, ...]:
    """The controller times (s, ``k·Ts`` of the row received next; ``t_rows`` the rows' wall
    receive times) at which PLANT_FAULTS reports a change of any gain or PLANT_TRUTH a
    change of the Stuck flag (a stuck sensor leaves the gains as they are)."""
    if len(t_rows) == 0:
        return ()
    changes: list[np.ndarray] = []
    if len(faults["t_s"]) >= 2:
        g = np.column_stack([faults[s] for s in ("KLoe", "KQ", "KDft")])
        i = np.flatnonzero(np.any(np.abs(np.diff(g, axis=0)) > GAIN_STEP, axis=1)) + 1
        changes.append(faults["t_s"][i])
    if len(truth["t_s"]) >= 2 and "Stuck" in truth:
        i = np.flatnonzero(np.diff(truth["Stuck"] > 0.5)) + 1
        changes.append(truth["t_s"][i])
    out = []
    for t_wall in np.sort(np.concatenate(changes)) if changes else ():
        j = min(int(np.searchsorted(t_rows, t_wall)), len(k) - 1)
        out.append(float(k[j] * ts))
    return tuple(out)


def _nearest(times: list[float], t: float, tol: float = EVENT_MATCH_S) -> int | None:
    """Index of the time in ``times`` nearest ``t`` within ``tol`` (s), or None."""
    if not times:
        return None
    i = min(range(len(times)), key=lambda j: abs(times[j] - t))
    return i if abs(times[i] - t) <= tol else None


def _agrees(seen: dict[str, Any], fields: dict[str, Any]) -> bool:
    """Whether a change seen on the bus is the scenario event's: some field of the event
    changed to its value, and none changed to another."""
    common = [k for k in BUS_VISIBLE if k in fields and k in seen]
    return bool(common) and all(abs(float(seen[k]) - float(fields[k])) <= GAIN_STEP * 2 for k in common)


#: injected kinds no other frame shows (PLANT_FAULTS has the gains, PLANT_TRUTH the stuck flag)
INJECTED_ONLY = ("position_bias_m", "frame_loss", "current_limit_a")


def injection_events(
    acks: dict[str, np.ndarray], codec: FrameCodec, t_rows: np.ndarray, k: np.ndarray, ts: float
) -> list[tuple[float, str]]:
    """``(t, words)`` of the injections the emulator applied (FAULT_INJECT_ACK frames ``acks``
    with ``Status`` APPLIED, names from ``codec``'s DBC) of a kind only that frame shows
    (:data:`INJECTED_ONLY`: a frame loss, a bias, a current limit), on the controller's time
    (``k·Ts`` of the row received next; ``t_rows`` the rows' wall receive times)."""
    if len(acks["t_s"]) == 0 or len(t_rows) == 0:
        return []
    msg = codec.message("FAULT_INJECT_ACK")
    kinds = {int(c): str(n) for c, n in (msg.get_signal_by_name("FaultKind").choices or {}).items()}
    codes = {str(n): int(c) for c, n in (msg.get_signal_by_name("Status").choices or {}).items()}
    applied = codes.get("APPLIED", -1)
    out = []
    for t_wall, kind, status, value in zip(
        acks["t_s"], acks["FaultKind"], acks["Status"], acks["Value"], strict=True
    ):
        name = kinds.get(int(kind), "")
        if int(status) != applied or name not in INJECTED_ONLY:
            continue
        j = min(int(np.searchsorted(t_rows, t_wall)), len(k) - 1)
        out.append((float(k[j] * ts), describe_changes({name: float(value)})))
    return out


def event_labels(
    r: SimResult, events: tuple[Any, ...] = (), known: tuple[tuple[float, str], ...] = ()
) -> list[tuple[float, str]]:
    """``(t, words)`` for each event of ``r``, sorted by t (s, the run's time axis).

    Every change the run saw (``r.event_times_s``: a log's PLANT_FAULTS gains and PLANT_TRUTH
    Stuck flag) is one event. A scenario event (``events``) is the next change that agrees
    with it (same new value: a real-time emulator's clock runs ahead of the controller's, so
    times differ by its start-up offset) and takes the scenario's words; a scenario event the
    bus cannot show (a bias, a frame loss, a current limit) is placed at its time plus that
    offset. The changes no scenario event explains (an injection from the monitor) are named
    from what changed; ``known``: times whose words are known already (:func:`injection_events`).
    Calling it again on times it produced gives the same events.
    """
    named = {float(t): words for t, words in known}
    free = [float(t) for t in r.event_times_s if float(t) not in named]
    seen = {t: _changes_at(r, t) for t in free}
    placed: list[tuple[float, str, float]] = []  # (time seen or NaN, words, scenario time)
    after = -math.inf
    for ev in events:
        fields = {k: v for k, v in vars(ev).items() if k != "t_s" and v is not None}
        i = next((j for j, t in enumerate(free) if t >= after and _agrees(seen[t], fields)), None)
        t = free.pop(i) if i is not None else math.nan
        after = t if i is not None else after
        placed.append((t, describe_changes(fields), float(ev.t_s)))
    offsets = [t - t_ev for t, _, t_ev in placed if math.isfinite(t)]
    offset = float(np.median(offsets)) if offsets else 0.0
    out = []
    for t, words, t_ev in placed:
        if not math.isfinite(t):
            i = _nearest(free, t_ev + offset)
            t = free.pop(i) if i is not None else t_ev + offset
        out.append((t, words))
    out += [(t, describe_changes(seen[t])) for t in free]
    out += [(t, w) for t, w in named.items() if t in {float(x) for x in r.event_times_s}]
    return sorted(out, key=lambda e: e[0])


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
