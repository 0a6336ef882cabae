"""The frames a controller loop sends besides VALVE_CMD, after each cycle: CTRL_STATUS (and the
CTRL_INDEX frames that follow it), CTRL_STATS, the heartbeat (:class:`.status_frames.FrameSchedule`
decides which is due), and the counter line of the log every ``stats_interval_s``."""

from __future__ import annotations

import logging
from typing import Protocol

from ..codec import FrameCodec
from .foreign import CollisionGuard
from .frameio import FrameIO
from .lifecycle import Lifecycle
from .loop_options import LoopOptions
from .status_frames import FrameSchedule, StatusReporter

log = logging.getLogger("ehpss_hil.controller")

#: CTRL_STATS CycleTimeMax's largest value (s): its 16-bit field in µs
CYCLE_TIME_MAX_S = 0.065535


class CycleView(Protocol):
    """What :meth:`PeriodicFrames.after_cycle` reads of the loop it serves (the daemon's
    :class:`~.controller_loop.ControllerLoop`, which owns a :class:`PeriodicFrames`), and the
    one call it makes back: this module stays below the loop."""

    @property
    def cycles(self) -> int: ...
    @property
    def overruns(self) -> int: ...
    @property
    def stale_frames(self) -> int: ...
    @property
    def failsafe_cycles(self) -> int: ...
    @property
    def reporter(self) -> StatusReporter: ...
    @property
    def io(self) -> FrameIO: ...
    @property
    def codec(self) -> FrameCodec: ...
    @property
    def life(self) -> Lifecycle: ...
    @property
    def guard(self) -> CollisionGuard: ...
    def send_status(self, all_index: bool = False) -> None: ...


class PeriodicFrames:
    """Which periodic frame is due after a cycle, and the compute-time maxima they report."""

    def __init__(self, opts: LoopOptions) -> None:
        self.schedule = FrameSchedule(
            round(opts.rate_hz / opts.status_rate_hz),
            round(opts.rate_hz / opts.stats_rate_hz),
            round(opts.rate_hz / opts.heartbeat_rate_hz),
        )
        self._log_every = round(opts.stats_interval_s * opts.rate_hz)
        #: the longest cycle compute (s) since the last CTRL_STATS, and since the last log line
        self.compute_max_s = 0.0
        self.interval_compute_max_s = 0.0
        self._logged_cycle = 0  # loop.cycles at the last after_cycle

    def record_compute(self, compute_s: float) -> None:
        """One cycle's compute time (s)."""
        self.compute_max_s = max(self.compute_max_s, compute_s)
        self.interval_compute_max_s = max(self.interval_compute_max_s, compute_s)

    def after_cycle(self, loop: CycleView) -> None:
        """The periodic frames due now (at most one of CTRL_STATUS, CTRL_STATS, heartbeat,
        CTRL_INDEX) and the counter line of the log."""
        c = loop.cycles
        reporter = loop.reporter
        due = self.schedule.next(c, bool(reporter.pending))
        if due.status:
            loop.send_status()
        if due.stats:
            loop.io.send(
                "CTRL_STATS",
                {
                    "FallbackReason": reporter.fallback_reason & 0xF,
                    "Overruns": loop.overruns & 0xFFFF,
                    "RejectedFrames": loop.codec.rejected & 0xFFFF,
                    "CycleTimeMax": min(self.compute_max_s, CYCLE_TIME_MAX_S),
                },
            )
            self.compute_max_s = 0.0
        if due.heartbeat:
            loop.io.send("HEARTBEAT_CTRL", {"NmtState": loop.life.nmt_state})
        if due.ctrl_index:
            reporter.send_next_index()
        prev, self._logged_cycle = self._logged_cycle, c
        if self._log_every and c // self._log_every > prev // self._log_every:
            self._log_counters(loop)

    def _log_counters(self, loop: CycleView) -> None:
        """Cheap counters only (no percentiles in the cycle: they would cost an overrun)."""
        log.info(
            "cycles %d, state %s, overruns %d, rejected frames %d, stale frames %d, "
            "fail-safe cycles %d, ID collisions: %s, second-transmitter episodes %d, "
            "max compute %.0f µs in the last interval",
            loop.cycles,
            loop.life.state.name,
            loop.overruns,
            loop.codec.rejected,
            loop.stale_frames,
            loop.failsafe_cycles,
            loop.io.collisions.text(),
            loop.guard.episodes,
            self.interval_compute_max_s * 1e6,
        )
        self.interval_compute_max_s = 0.0
