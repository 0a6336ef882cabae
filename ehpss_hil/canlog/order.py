"""A log's frames put in time order as they stream past, with a bounded buffer.

A logger writes frames nearly in time order: a frame stamped at send and one stamped at receive
may swap places by a few milliseconds, never by more than a few hundred frames. :class:`TimeOrder`
holds the newest :data:`REORDER_WINDOW_FRAMES` frames in a heap and hands on the oldest, so such
swaps come out sorted and memory stays bounded whatever the length of the log.

A frame older than one already handed on lies *behind the window*: either the wall clock stepped
back (NTP, ``date -s``) or the lines are not in time order at all (a reversed or shuffled file).
At a step every frame held is handed on first (the frames before the step in file order come
first, as they happened), then the late frame; a handful of such steps is a clock that was set
back, more than :data:`MAX_BEHIND_FRAMES` is a file out of time order and a :class:`LogError`
(one line) — never an array sorted in memory.
"""

from __future__ import annotations

import heapq
from pathlib import Path
from typing import Generic, TypeVar

from .files import LogError

#: frames held to put a log's small swaps in time order (≈ 1 s of a 1 kHz bench log, whose
#: cycles log 4–5 frames each); memory is this many frames
REORDER_WINDOW_FRAMES = 4096
#: frames behind the window (older than one already handed on) a log may hold: each is a step
#: back of the wall clock; more is a log whose lines are not in time order
MAX_BEHIND_FRAMES = 64

T = TypeVar("T")


class OutOfOrderError(LogError):
    """A log's lines are not in time order (reversed, shuffled) beyond the reorder window."""


class TimeOrder(Generic[T]):
    """Items keyed by a timestamp (s), handed on in time order through a bounded heap (module
    docstring). ``push`` returns the items now due, :meth:`drain` the rest at the end."""

    def __init__(
        self, source: Path, window: int = REORDER_WINDOW_FRAMES, max_behind: int = MAX_BEHIND_FRAMES
    ) -> None:
        self.source = source
        self.window = window
        self.max_behind = max_behind
        self._heap: list[tuple[float, int, T]] = []
        self._seq = 0
        self._last_s = float("-inf")
        #: frames found behind the window (clock steps back), with the first one's position
        self.behind = 0
        self.first_behind: tuple[int, float, float] | None = None

    def push(self, t_s: float, item: T) -> list[T]:
        """Add one item stamped ``t_s`` (s); the items due now, oldest first."""
        self._seq += 1
        if t_s < self._last_s:
            return self._behind(t_s, item)
        heapq.heappush(self._heap, (t_s, self._seq, item))
        if len(self._heap) <= self.window:
            return []
        t0, _, oldest = heapq.heappop(self._heap)
        self._last_s = t0
        return [oldest]

    def _behind(self, t_s: float, item: T) -> list[T]:
        self.behind += 1
        if self.first_behind is None:
            self.first_behind = (self._seq, t_s, self._last_s)
        if self.behind > self.max_behind:
            n, t, last = self.first_behind
            raise OutOfOrderError(
                f"{self.source}: lines not in time order: more than {self.max_behind} frames lie "
                f"further back in time than the {self.window}-frame reorder window reaches (the "
                f"first: frame {n}, t={t:.6f} after t={last:.6f}); sort the log by time"
            )
        due = self.drain()
        due.append(item)
        self._last_s = t_s
        return due

    def drain(self) -> list[T]:
        """Every item still held, oldest first."""
        due = [item for _, _, item in sorted(self._heap)]
        if self._heap:
            self._last_s = max(t for t, _, _ in self._heap)
        self._heap.clear()
        return due
