"""A log's wall clock checked against the controller's cycle counter, and clock steps undone.

A log's timestamps are the host's wall clock (CLOCK_REALTIME at send or receive): an NTP step or
a ``date -s`` in the middle of a run moves every later timestamp by the step, and a report that
pairs frames by timestamp then pairs the wrong ones. In a realtime run the controller's
VALVE_CMD ``CycleCount`` counts its periods whatever the wall clock does (an overrun's skipped
periods are counted too), so ``t − CycleCount·Ts`` stays within a few periods for a whole run:
where it changes by more than :data:`CLOCK_STEP_MIN_S` between two consecutive commands and
stays changed (the medians of the commands each side differ by as much) the wall clock disagrees
with the cycle clock, and that is a clock step — a mere gap in the timestamps is not (the
counter runs on through a pause), nor is one late command. :func:`undo_clock_steps` finds each step, where in
the file it happened (the largest timestamp jump between those two commands, in file order) and
moves every frame logged after it back by the step, so that frames of all names line up again.

In a lockstep run the wall clock does not follow the cycles at all (a cycle takes as long as
the exchange of its frames; a pause of either process stops the counter), so a forward gap is
just a pause and never a step. A run is lockstep when its metadata says so (the sidecar's
``lockstep``/``mode``, ``run.json``), or, when the metadata does not say, when the wall time per
counted cycle is off the sample time by more than :data:`REALTIME_RATE_TOLERANCE` (a candump
of a lockstep run has no sidecar). There, as in a log without VALVE_CMD, only file order is
left: a backward jump of more than :data:`CLOCK_STEP_MIN_S` (time never runs backwards) is
undone; a forward one (of more than :data:`CLOCK_STEP_S`) is kept — reported only when there is
no VALVE_CMD at all (it cannot be told from a pause of every sender). A backward jump too small
to be a step but larger than :data:`SMALL_STEP_NOTE_S` is noted and left as logged: a step of
any size back leaves a note.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..canlog.reader import FRAME_INDEX

#: a forward jump in file order larger than this (s) is reported where no VALVE_CMD counter can
#: tell a clock step from a pause of every sender
CLOCK_STEP_S = 0.5
#: a change of ``t − CycleCount·Ts`` larger than this (s) that persists (the medians of
#: :data:`STEP_WINDOW` commands each side differ by as much), or a backward jump in file order
#: larger than this, is a clock step: a controller's jitter moves single commands and its
#: overruns are counted, the log's own reordering (receive vs send stamps) is a few ms
CLOCK_STEP_MIN_S = 0.01
#: a backward jump in file order smaller than a step but larger than this (s) is noted, not
#: undone: a logger's own reordering of send and receive stamps stays below
SMALL_STEP_NOTE_S = 0.003
#: commands on each side of a step whose offsets (median) give its size: jitter averages out
STEP_WINDOW = 16
#: commands a small step (below :data:`CLOCK_STEP_S`) needs on each side to be confirmed
STEP_MIN_SIDE = 4
#: a step's size is rounded to the log's resolution (candump -L: 1 µs)
STEP_RESOLUTION_S = 1e-6
#: a log without lockstep/realtime metadata is taken as realtime when its median wall time per
#: counted cycle is within this fraction of the sample time (a realtime loop keeps Ts on the
#: median even with overruns, which are counted; a lockstep run goes as fast as its frames)
REALTIME_RATE_TOLERANCE = 0.1

Frames = dict[str, dict[str, np.ndarray]]


@dataclass(frozen=True)
class ClockStep:
    """One step of the log's clock: the first frame after it (file order), the wall-clock time
    before it (s) and its size (s; negative: the clock went back)."""

    frame_index: int
    before_s: float
    step_s: float

    def text(self) -> str:
        """``+3600.000 s after 1767225600.600`` (the uncorrected time before the step)."""
        return f"{self.step_s:+.3f} s after t={self.before_s:.6f} (frame {self.frame_index})"


def unwrap_counter(c: np.ndarray, modulo: int = 65536) -> np.ndarray:
    """A wrapping counter made monotonic (assumes < ``modulo`` steps between two rows)."""
    if len(c) == 0:
        return c.astype(np.int64)
    d = np.mod(np.diff(c.astype(np.int64)), modulo)
    return np.concatenate(([int(c[0])], int(c[0]) + np.cumsum(d)))


def undo_clock_steps(
    frames: Frames, ts_s: float | None, lockstep: bool | None = None
) -> tuple[list[ClockStep], list[str]]:
    """Find the clock steps of ``frames`` (decoded with ``order``: each name has
    :data:`FRAME_INDEX`) and move the timestamps after each back by it, in place; returns the
    steps undone and one-line notes. ``lockstep``: what the run's metadata says (None: not
    said, judged from the timing; see the module docstring)."""
    t_all, base = _file_order_times(frames)
    if len(t_all) == 0:
        return [], []
    cmd = frames.get("VALVE_CMD")
    notes: list[str] = []
    counted = cmd if cmd is not None and len(cmd["t_s"]) > 1 and "CycleCount" in cmd else None
    has_counter = counted is not None
    follows = counted is not None and clock_follows_cycles(counted, ts_s, lockstep, notes)
    if counted is not None and follows:
        steps = _steps_from_cycle_count(counted, t_all, ts_s, base)
    else:
        steps, jumps = _steps_from_file_order(t_all, base)
        if jumps and not has_counter:
            notes.append(
                "log timestamps jump forward by "
                + ", ".join(j.text() for j in jumps)
                + ": no VALVE_CMD CycleCount to tell a clock step from a pause, kept as logged"
            )
    if steps:
        _shift(frames, steps)
        how = (
            "on the VALVE_CMD CycleCount"
            if follows
            else "in file order (time never runs backwards; "
            + ("a lockstep run's clock does not follow its cycles)" if has_counter else "no VALVE_CMD)")
        )
        notes.insert(
            0,
            "the log's clock stepped "
            + ", ".join(s.text() for s in steps)
            + ": timestamps after each step corrected "
            + how,
        )
    small = _small_steps_back(t_all, steps, base)
    if small:
        notes.append(small)
    return steps, notes


def _small_steps_back(t_all: np.ndarray, steps: list[ClockStep], base: int = 0) -> str:
    """A note on the backward jumps in file order larger than :data:`SMALL_STEP_NOTE_S` that
    were not undone as steps (too small to tell from jitter), or empty; ``t_all[i]`` is frame
    ``base + i``."""
    known = np.flatnonzero(np.isfinite(t_all)) + base
    d = np.diff(t_all[known - base])
    back = np.flatnonzero(d < -SMALL_STEP_NOTE_S)
    undone = {s.frame_index for s in steps}
    back = np.array([j for j in back if int(known[j + 1]) not in undone], dtype=np.int64)
    if len(back) == 0:
        return ""
    first = int(back[0])
    return (
        f"the log's timestamps run back by up to {-float(np.min(d[back])) * 1e3:.3f} ms at "
        f"{len(back)} place(s) (the first after t={float(t_all[known[first] - base]):.6f}, frame "
        f"{int(known[first + 1])}): left as logged, a step must exceed "
        f"{CLOCK_STEP_MIN_S * 1e3:g} ms to be told from jitter and reordering"
    )


def clock_follows_cycles(
    cmd: dict[str, np.ndarray], ts_s: float | None, lockstep: bool | None, notes: list[str]
) -> bool:
    """True when the wall clock of a log should keep the VALVE_CMD cycle clock (realtime): the
    metadata's word, else the median wall time per counted cycle within
    :data:`REALTIME_RATE_TOLERANCE` of ``ts_s`` (without ``ts_s``: taken as realtime)."""
    if lockstep is not None:
        return not lockstep
    per = _period(cmd["t_s"], unwrap_counter(cmd["CycleCount"]))
    if not ts_s or per is None or abs(per / ts_s - 1.0) <= REALTIME_RATE_TOLERANCE:
        return True
    notes.append(
        f"the log's wall clock ran {per / ts_s:.2f} × the cycle clock (median {per * 1e3:.3f} ms "
        f"per cycle, Ts = {ts_s * 1e3:g} ms) and no metadata says realtime or lockstep: taken as "
        "a lockstep run, where a gap in the timestamps is a pause"
    )
    return False


def _file_order_times(frames: Frames) -> tuple[np.ndarray, int]:
    """``(t_all, base)``: every decoded frame's timestamp at its position in the log (NaN: a
    frame not decoded), ``t_all[i]`` for frame ``base + i`` (``base``: the first frame given, so
    a part of a long log costs its own length)."""
    held = [f[FRAME_INDEX].astype(np.int64) for f in frames.values() if len(f["t_s"])]
    if not held:
        return np.zeros(0), 0
    base = min(int(i.min()) for i in held)
    t_all = np.full(1 + max(int(i.max()) for i in held) - base, np.nan)
    for f in frames.values():
        if len(f["t_s"]):
            t_all[f[FRAME_INDEX].astype(np.int64) - base] = f["t_s"]
    return t_all, base


def _steps_from_cycle_count(
    cmd: dict[str, np.ndarray], t_all: np.ndarray, ts_s: float | None, base: int = 0
) -> list[ClockStep]:
    t, at = cmd["t_s"], cmd[FRAME_INDEX].astype(np.int64) - base
    k = unwrap_counter(cmd["CycleCount"])
    ts = ts_s if ts_s else _period(t, k)
    if ts is None:
        return []
    off = t - k * ts
    steps = []
    for j, size in _persistent_cuts(off):
        where = _largest_jump(t_all, int(at[j]), int(at[j + 1]), size)
        steps.append(ClockStep(where + base, float(t_all[_known_before(t_all, where)]), size))
    return steps


def _persistent_cuts(off: np.ndarray) -> list[tuple[int, float]]:
    """``(j, size)`` for each clock step between commands ``j`` and ``j + 1``: a change of the
    offset ``off`` larger than :data:`CLOCK_STEP_S` (sized on the medians of up to
    :data:`STEP_WINDOW` offsets each side, up to the neighbouring steps), or one larger than
    :data:`CLOCK_STEP_MIN_S` that persists — the medians of :data:`STEP_WINDOW` offsets each
    side (at least :data:`STEP_MIN_SIDE`) differ by as much: a few late commands are no step."""
    d = np.abs(np.diff(off))
    big = np.flatnonzero(d > CLOCK_STEP_S)
    bounds = np.concatenate(([0], big + 1, [len(off)]))
    out = []
    for j in np.flatnonzero(d > CLOCK_STEP_MIN_S):
        n = int(np.searchsorted(big, j))  # big steps before j: j lies in segment n
        lo = int(bounds[n])
        hi = int(bounds[n + 2] if n < len(big) and big[n] == j else bounds[n + 1])
        before = off[max(lo, j + 1 - STEP_WINDOW) : j + 1]
        after = off[j + 1 : min(hi, j + 1 + STEP_WINDOW)]
        size = float(np.median(after) - np.median(before))
        is_big = d[j] > CLOCK_STEP_S
        if not is_big and (min(len(before), len(after)) < STEP_MIN_SIDE or abs(size) <= CLOCK_STEP_MIN_S):
            continue
        out.append((int(j), round(size / STEP_RESOLUTION_S) * STEP_RESOLUTION_S))
    return out


def _steps_from_file_order(t_all: np.ndarray, base: int = 0) -> tuple[list[ClockStep], list[ClockStep]]:
    """(backward steps to undo, forward jumps to report) from the timestamps in file order
    (``t_all[i]``: frame ``base + i``)."""
    known = np.flatnonzero(np.isfinite(t_all))
    d = np.diff(t_all[known])
    usual = float(np.median(d[d >= 0])) if np.any(d >= 0) else 0.0
    back, fwd = [], []
    for j in np.flatnonzero((d > CLOCK_STEP_S) | (d < -CLOCK_STEP_MIN_S)):
        step = ClockStep(int(known[j + 1]) + base, float(t_all[known[j]]), float(d[j]))
        if d[j] < 0:
            size = round((float(d[j]) - usual) / STEP_RESOLUTION_S) * STEP_RESOLUTION_S
            back.append(ClockStep(step.frame_index, step.before_s, size))
        else:
            fwd.append(step)
    return back, fwd


def _largest_jump(t_all: np.ndarray, lo: int, hi: int, size: float) -> int:
    """The first frame after the largest timestamp jump in the direction of ``size`` among the
    frames ``lo``…``hi`` (file order; the two commands around the step)."""
    idx = lo + np.flatnonzero(np.isfinite(t_all[lo : hi + 1]))
    d = np.diff(t_all[idx]) * (1.0 if size > 0 else -1.0)
    return int(idx[int(np.argmax(d)) + 1]) if len(d) else hi


def _known_before(t_all: np.ndarray, i: int) -> int:
    known = np.flatnonzero(np.isfinite(t_all[:i]))
    return int(known[-1]) if len(known) else i


def _period(t: np.ndarray, k: np.ndarray) -> float | None:
    """Ts (s) from consecutive commands: the median time per counted period."""
    dk, dt = np.diff(k), np.diff(t)
    ok = dk > 0
    return float(np.median(dt[ok] / dk[ok])) if np.any(ok) else None


def _shift(frames: Frames, steps: list[ClockStep]) -> None:
    """Move every frame logged after a step back by it (the steps in file order)."""
    order = sorted(steps, key=lambda s: s.frame_index)
    starts = np.array([s.frame_index for s in order])
    total = np.concatenate(([0.0], np.cumsum([s.step_s for s in order])))
    for f in frames.values():
        if len(f["t_s"]):
            n = np.searchsorted(starts, f[FRAME_INDEX], side="right")
            f["t_s"] = f["t_s"] - total[n]
