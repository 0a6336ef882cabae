"""The controller's status on the bus: CTRL_STATUS and its CTRL_INDEX snapshot (DBC frames),
and the schedule of the periodic frames.

One :class:`StatusReporter` per controller loop: :meth:`StatusReporter.send` puts CTRL_STATUS
out now and queues one CTRL_INDEX per model slot (J and θ), which the loop sends one per
following cycle (or all at once), so that no cycle carries nine frames. :class:`FrameSchedule`
says which periodic frame a cycle sends.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..control.base import Controller
from ..control.registry import MODE_CODE
from .frameio import FrameIO
from .lifecycle import Lifecycle

#: CTRL_STATUS ``Mode`` values
#: CTRL_STATUS ``Mode`` of a mode not in the registry's :data:`MODE_CODE`
MODE_UNKNOWN = 7
_F32_MAX = 3.0e38


class StatusReporter:
    """CTRL_STATUS + queued CTRL_INDEX frames of one controller."""

    def __init__(self, io: FrameIO) -> None:
        self.io = io
        #: (slot, J, θ) still to send, the next one last
        self.pending: list[tuple[int, float, float]] = []
        #: the do-no-harm monitor at the last CTRL_STATUS: reason now (0: none), entries so far
        self.fallback_reason = 0
        self.fallbacks = 0

    def send(self, controller: Controller, life: Lifecycle, all_index: bool = False) -> None:
        """``controller``'s CTRL_STATUS now; the CTRL_INDEX frames (one per model slot) queued,
        or all sent at once with ``all_index``."""
        s = controller.status()
        self.io.send(
            "CTRL_STATUS",
            {
                "State": int(life.state),
                "FailsafeReason": int(life.reason),
                "Mode": MODE_CODE.get(controller.mode, MODE_UNKNOWN),
                "NominalFallback": int(s.fallback),
                "ActiveSpoolModel": _nibble(s.active_model.get("spool", 0)),
                "ActivePosModel": _nibble(s.active_model.get("position", 0)),
                "KLoeHat": _clip(s.k_loe_hat, 0.0, 4.095),
                "KDftHat": _clip(s.k_dft_hat, 0.0, 4.095),
                "Switches": min(s.switches, 255),
            },
        )
        self.fallback_reason = s.fallback_reason
        self.fallbacks = s.fallbacks
        self.pending = [
            (slot, j, s.theta.get(slot, 0.0)) for slot, j in reversed(s.index.items()) if 0 <= slot <= 15
        ]
        while all_index and self.pending:
            self.send_next_index()

    def send_next_index(self) -> None:
        """The next queued CTRL_INDEX (J dimensionless, θ the model's gain)."""
        slot, j, theta = self.pending.pop()
        self.io.send(
            "CTRL_INDEX",
            {
                "ModelSlot": slot,
                f"J_{slot}": _clip(j, -_F32_MAX, _F32_MAX),
                f"Theta_{slot}": _clip(theta, 0.0, 6.5535),
            },
        )


def _clip(v: float, lo: float, hi: float) -> float:
    if not math.isfinite(v):
        return hi if v > 0 else lo
    return max(lo, min(hi, v))


def _nibble(v: int) -> int:
    return int(v) & 0x0F


class Due(NamedTuple):
    """The periodic frames one cycle sends."""

    status: bool
    stats: bool
    heartbeat: bool
    ctrl_index: bool


class FrameSchedule:
    """CTRL_STATUS, CTRL_STATS and the heartbeat every so many cycles, the queued CTRL_INDEX
    frames in the cycles between, at most one of them per cycle.

    CTRL_STATUS goes out when due; a CTRL_STATS or heartbeat that fell due with it goes out one
    and two cycles later; otherwise the next CTRL_INDEX of the snapshot. (A frame sent every
    cycle does not take the slot.) A frame falls due when the cycle count reaches a multiple of
    its period, also when the count jumped over it (periods skipped by an overrun).
    """

    def __init__(self, status_every: int, stats_every: int, heartbeat_every: int) -> None:
        self.status_every = max(1, status_every)
        self.stats_every = max(1, stats_every)
        self.heartbeat_every = max(1, heartbeat_every)
        self._last = 0  # the cycle count at the last call
        self._stats_due = False
        self._hb_due = False

    def next(self, cycles: int, index_pending: bool) -> Due:
        """The frames to send now, ``cycles`` cycles after the start (non-decreasing)."""
        c, prev = cycles, self._last
        self._last = c
        self._stats_due = self._stats_due or c // self.stats_every > prev // self.stats_every
        self._hb_due = self._hb_due or c // self.heartbeat_every > prev // self.heartbeat_every
        status = c // self.status_every > prev // self.status_every
        busy = status and self.status_every > 1
        stats = self._stats_due and not busy
        if stats:
            self._stats_due = False
            busy = self.stats_every > 1
        heartbeat = self._hb_due and not busy
        if heartbeat:
            self._hb_due = False
            busy = self.heartbeat_every > 1
        return Due(status, stats, heartbeat, index_pending and not busy and not status)
