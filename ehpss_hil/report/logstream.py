"""A log of any length cut into chunks of controller samples, each laid out as :mod:`.logdata`
lays out a whole log, with what crosses a chunk boundary carried over.

The frames are decoded once, in file order (:func:`~ehpss_hil.canlog.decode.decoded_frames`);
every :data:`CHUNK_SAMPLES` VALVE_CMD frames the frames held so far become one
:class:`ChunkRows`: the samples up to the newest command, each signal the newest frame logged
before it (the same :func:`~.logdata.hold`, ``_assemble`` and reference model as the whole log).
Carried from one chunk to the next, so that a sample's values do not depend on where the cut
fell: the newest frame of every name (the value held across the boundary, the previous gains an
event is a change from, the previous CTRL_STATUS), the last :data:`~.logclock.STEP_WINDOW`
commands (their unwrapped ``CycleCount``: missing commands at the boundary are interpolated
between the two chunks' commands, and a clock step at the boundary has commands on both sides),
the reference model's state, the clock steps found so far (later frames are moved by them
before they are looked at) and whether the wall clock follows the cycles (decided once, on the
first chunk). Frames stamped after the chunk's last sample wait for the next chunk; samples after
the newest PLANT_TRUTH wait too (a log's last samples after the emulator stopped are dropped,
as :mod:`.logdata` drops them, and only at the end of the log is that known).

Memory: one chunk's frames and samples (``CHUNK_SAMPLES`` × ≈ 1 kB), whatever the log's length.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import limits
from ..canlog.decode import Columns, TooLongError, decoded_frames
from ..canlog.reader import FRAME_INDEX, BadLines, LogError
from ..codec import FrameCodec
from ..physics.params import Params
from ..physics.reference import ReferenceModel
from .annotate import injection_events
from .logbounds import check_sample_time, check_span
from .logclock import STEP_WINDOW, ClockStep, clock_follows_cycles, undo_clock_steps, unwrap_counter
from .logdata import _assemble, _median_period, _sorted, rows_with_truth
from .logmeta import RunInfo
from .result import SimResult

#: controller samples laid out at once: ≈ 50 MB of frames and per-sample arrays at 1 kHz
CHUNK_SAMPLES = 50_000
#: a chunk waits for PLANT_TRUTH (samples after the newest one) for at most this many chunks'
#: commands, then lays its samples out anyway: a bounded wait on a log whose emulator stopped
MAX_DEFERRED_CHUNKS = 4

#: a CycleCount step between two consecutive commands larger than this (half the 16-bit
#: counter's range) is a jump back, not periods skipped: a streamed log is refused there
MAX_COMMAND_GAP = 32_768

Frames = dict[str, dict[str, np.ndarray]]


@dataclass
class ChunkRows:
    """One chunk: its samples (``result``, global ``t = k·Ts``), commanded current (A), the
    frames they were laid out from (the previous chunk's newest of each name first), the rows'
    wall times (s) and the injections the chunk's FAULT_INJECT_ACK frames show."""

    result: SimResult
    commanded_a: np.ndarray
    frames: Frames
    t_rows: np.ndarray
    injections: list[tuple[float, str]]
    #: wall time (s) of the previous chunk's last sample (−inf for the first chunk)
    t_before: float


@dataclass
class StreamState:
    """What the stream learned about the whole log (filled while the chunks are read)."""

    ts_s: float | None
    frame_counts: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    steps: list[ClockStep] = field(default_factory=list)
    missing_commands: int = 0
    dropped_after_truth: int = 0
    had_commands: bool = False
    enabled: bool = False


def _concat(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Rows of one frame name from several parts; a column a part lacks is NaN there."""
    parts = [p for p in parts if len(p["t_s"])]
    if not parts:
        return {"t_s": np.zeros(0)}
    keys = list(dict.fromkeys(k for p in parts for k in p))
    return {
        k: np.concatenate([p[k] if k in p else np.full(len(p["t_s"]), np.nan) for p in parts]) for k in keys
    }


def _take(f: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, np.ndarray]:
    return {k: v[mask] for k, v in f.items()}


class LogStream:
    """Iterate over a log's :class:`ChunkRows` (module docstring)."""

    def __init__(
        self,
        log: Path,
        codec: FrameCodec,
        info: RunInfo,
        params: Params,
        bad: BadLines,
        chunk_samples: int = CHUNK_SAMPLES,
    ) -> None:
        self.log, self.codec, self.info, self.bad = log, codec, info, bad
        #: commands per chunk: at most half the samples a chunk may lay out (a few missing)
        self.chunk = max(1, min(chunk_samples, limits.MAX_LOG_SAMPLES // 2))
        self.state = StreamState(info.ts_s)
        self.params = params
        self.refmodel: ReferenceModel | None = None
        self.carry: Frames = {}  # the newest frame of each name (commands: the last few)
        self.waiting: Frames = {}  # frames stamped after the last laid-out sample
        self.shift: list[ClockStep] = []
        self.follows: bool | None = None if info.lockstep is None else not info.lockstep
        self.start_k: int | None = None  # unwrapped CycleCount of the first enabled command
        self.next_k = 0
        self.t_last = -np.inf
        self.last_truth = -np.inf

    def chunks(self) -> Iterator[ChunkRows]:
        """Decode the log once and yield its chunks in time order."""
        new: dict[str, Columns] = {}
        commands = held = 0
        for i, name, t_s, values in decoded_frames(self.log, self.codec, self.bad):
            cols = new.setdefault(name, Columns())
            held -= cols.cells
            cols.add(t_s, {**values, FRAME_INDEX: i})
            held += cols.cells
            self.state.frame_counts[name] = self.state.frame_counts.get(name, 0) + 1
            commands += name == "VALVE_CMD"
            if commands >= self.chunk or held > limits.MAX_LOG_VALUES:
                yield from self._flush({n: c.arrays() for n, c in new.items()}, False, commands == 0)
                new, commands, held = {}, 0, 0
        yield from self._flush({n: c.arrays() for n, c in new.items()}, True, False)

    # ---- one chunk ------------------------------------------------------------------------
    def _flush(self, new: Frames, final: bool, no_commands: bool) -> Iterator[ChunkRows]:
        if no_commands and not self.state.had_commands:
            raise TooLongError(
                f"{self.log}: too long to report: more than {limits.MAX_LOG_VALUES} decoded signal values "
                "without a VALVE_CMD frame (a long log is laid out per controller command)"
            )
        for f in new.values():
            f["t_s"] = f["t_s"] - self._shift_at(f[FRAME_INDEX])
        names = set(self.carry) | set(self.waiting) | set(new)
        frames = {n: _concat([self.carry.get(n, {"t_s": np.zeros(0)}), *self._parts(n, new)]) for n in names}
        self._clock(frames)
        rows = self._rows(frames, final)
        if rows is None:
            return
        yield rows

    def _parts(self, name: str, new: Frames) -> list[dict[str, np.ndarray]]:
        return [p for p in (self.waiting.get(name), new.get(name)) if p is not None]

    def _shift_at(self, index: np.ndarray) -> np.ndarray:
        """The total of the clock steps found before each frame index (s)."""
        if not self.shift:
            return np.zeros(len(index))
        starts = np.array([s.frame_index for s in self.shift])
        total = np.concatenate(([0.0], np.cumsum([s.step_s for s in self.shift])))
        return total[np.searchsorted(starts, index, side="right")]

    def _clock(self, frames: Frames) -> None:
        """Clock steps of this chunk (with the carried commands before it), undone in place."""
        cmd = frames.get("VALVE_CMD")
        if self.follows is None and cmd is not None and len(cmd["t_s"]) > 1:
            self.follows = clock_follows_cycles(cmd, self.state.ts_s, None, self.state.notes)
        lockstep = None if self.follows is None else not self.follows
        steps, notes = undo_clock_steps(frames, self.state.ts_s, lockstep)
        known = {s.frame_index for s in self.shift}
        fresh = [s for s in steps if s.frame_index not in known]
        self.shift = sorted([*self.shift, *fresh], key=lambda s: s.frame_index)
        self.state.steps += fresh
        for n in notes:
            if n not in self.state.notes:
                self.state.notes.append(n)

    def _commands(self, frames: Frames) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(k, wall time, setpoint, file index)`` of the commands in play (from the first
        enabled one on), k the unwrapped ``CycleCount`` counted from it."""
        cmd = frames.get("VALVE_CMD", {"t_s": np.zeros(0)})
        if not len(cmd["t_s"]):
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0)
        self.state.had_commands = True
        cyc = unwrap_counter(cmd["CycleCount"])
        if "_k" in cmd and np.isfinite(cmd["_k"][0]):
            cyc = cyc - cyc[0] + int(cmd["_k"][0])  # continue the carried commands' count
        first = 0
        if self.start_k is None:
            on = np.flatnonzero(cmd["Enable"] > 0.5)
            if len(on) == 0:
                return np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0)
            first, self.start_k = int(on[0]), int(cyc[on[0]])
            self.state.enabled = True
        cmd["_k"] = cyc.astype(float)
        k = cyc[first:] - self.start_k
        return k, cmd["t_s"][first:], cmd["CurrentSetpoint"][first:], cmd[FRAME_INDEX][first:]

    def _rows(self, frames: Frames, final: bool) -> ChunkRows | None:
        k_cmd, t_cmd, i_set, _ = self._commands(frames)
        truth = frames.get("PLANT_TRUTH", {"t_s": np.zeros(0)})
        if len(truth["t_s"]):
            self.last_truth = max(self.last_truth, float(np.max(truth["t_s"])))
        ts = self.state.ts_s
        cut = np.inf if final else (float(t_cmd[-1]) if len(t_cmd) else -np.inf)
        if not final and ts is not None and np.isfinite(self.last_truth):
            waited = np.count_nonzero(t_cmd > self.last_truth + 1.5 * ts)
            if waited < MAX_DEFERRED_CHUNKS * self.chunk:
                cut = min(cut, self.last_truth + 1.5 * ts)
        usable = (t_cmd <= cut) & (k_cmd >= self.next_k)
        if not np.any(usable):  # not yet enabled: only the newest frames matter (held values)
            self._keep(frames, self.t_last if self.start_k is not None else np.inf)
            return None
        jumps = np.flatnonzero(np.abs(np.diff(k_cmd)) > MAX_COMMAND_GAP)
        if len(jumps):
            raise LogError(
                f"{self.log}: its VALVE_CMD CycleCount jumps by {int(k_cmd[jumps[0] + 1] - k_cmd[jumps[0]])} "
                f"samples after sample {int(k_cmd[jumps[0]])} (more than half its 16-bit range: it ran "
                "back; logs of several runs joined?): report each run on its own"
            )
        k_hi = int(k_cmd[usable][-1])
        check_span(self.log, k_hi + 1 - self.next_k, int(np.count_nonzero(usable)), "VALVE_CMD")
        if k_hi + 1 > limits.MAX_STREAMED_SAMPLES:
            raise TooLongError(
                f"{self.log}: too long to report: more than {limits.MAX_STREAMED_SAMPLES} controller "
                "samples (a report's scratch file and time grow with them): cut the log (candump "
                "lines stand alone: head -n)"
            )
        k = np.arange(self.next_k, k_hi + 1)
        inplay = k_cmd <= k_hi
        t_rows = np.interp(k, k_cmd[inplay], t_cmd[inplay])
        i_cmd = np.full(len(k), np.nan)
        mine = inplay & (k_cmd >= self.next_k)
        i_cmd[k_cmd[mine] - self.next_k] = i_set[mine]
        self.state.missing_commands += len(k) - len(np.unique(k_cmd[mine]))
        if ts is None:
            ts = self.state.ts_s = _median_period(t_rows) or 1e-3
            self.state.notes.append(
                f"sample time not in the metadata: {ts * 1e3:.4g} ms from the log's timing"
            )
            check_sample_time(self.log, ts, "from the log's timing")
        if final and np.isfinite(self.last_truth):
            pos = frames.get("SENSOR_POS", {"t_s": np.zeros(0)})["t_s"]
            keep = rows_with_truth(t_rows, self.last_truth, pos, ts, self.t_last)
            self.state.dropped_after_truth += len(k) - int(np.count_nonzero(keep))
            k, t_rows, i_cmd = k[keep], t_rows[keep], i_cmd[keep]
        if len(k) == 0:
            return None
        return self._layout(frames, k, t_rows, i_cmd, ts)

    def _layout(
        self, frames: Frames, k: np.ndarray, t_rows: np.ndarray, i_cmd: np.ndarray, ts: float
    ) -> ChunkRows:
        t_end = float(t_rows[-1])
        used = {n: _take(f, f["t_s"] <= t_end) for n, f in frames.items()}
        self._keep(frames, t_end)
        x_d, y_m = self._reference(k, ts)
        notes: list[str] = []
        result, _ = _assemble(used, None, self.info, k, t_rows, ts, x_d, y_m, notes)
        pos = _sorted(used, "SENSOR_POS")["t_s"]
        if len(pos) and len(k):  # fresh: a SENSOR_POS since the previous sample, in the last chunk too
            result.fresh[0] = np.searchsorted(pos, t_rows[0], "right") > np.searchsorted(
                pos, self.t_last, "right"
            )
        acks = _sorted({n: f for n, f in used.items() if n == "FAULT_INJECT_ACK"}, "FAULT_INJECT_ACK")
        acks = _take(acks, acks["t_s"] > self.t_last) if len(acks["t_s"]) else acks
        inj = injection_events(acks, self.codec, t_rows, k, ts)
        before, self.t_last, self.next_k = self.t_last, t_end, int(k[-1]) + 1
        return ChunkRows(result, i_cmd, used, t_rows, inj, before)

    def _keep(self, frames: Frames, t_end: float) -> None:
        """Carry the newest frame of each name up to ``t_end`` (commands: the last
        :data:`STEP_WINDOW`); frames stamped later wait for the next chunk."""
        self.carry, self.waiting = {}, {}
        for n, f in frames.items():
            early = f["t_s"] <= t_end
            late = ~early
            if np.any(late):
                self.waiting[n] = _take(f, late)
            idx = np.flatnonzero(early)
            if len(idx):
                last = STEP_WINDOW if n == "VALVE_CMD" else 1
                order = idx[np.argsort(f["t_s"][idx], kind="stable")][-last:]
                self.carry[n] = _take(f, np.sort(order))

    def _reference(self, k: np.ndarray, ts: float) -> tuple[np.ndarray, np.ndarray]:
        """x_d and y_m (m) of samples ``k`` (contiguous, continuing the previous chunk)."""
        ref, sc = self.info.reference, self.info.scenario
        if ref is None:
            return np.full(len(k), np.nan), np.full(len(k), np.nan)
        base = Path(sc.base_dir) if sc is not None and sc.base_dir else None
        x_d = ref.sample(k * ts, base)
        if self.refmodel is None:
            self.refmodel = ReferenceModel(self.params, ts)
        return x_d, self.refmodel.run(x_d)


__all__ = ["CHUNK_SAMPLES", "ChunkRows", "LogStream", "StreamState"]
