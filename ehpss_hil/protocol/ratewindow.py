"""Frames of one transmitter counted per control period over a window: more than one
transmitter at one frame per period delivers is evidence of a second one (a second SENSOR_POS
stream: :class:`ehpss_hil.runtime.foreign.SensorStreams`; another SYNC producer:
:class:`ehpss_hil.protocol.cia408.master.CyclicMaster`)."""

from __future__ import annotations

#: control periods over which distinct SENSOR_POS frames are counted against one sensor's rate
SENSOR_RATE_WINDOW_CYCLES = 40
#: one sensor delivers at most this many frames per period over the window (late deliveries
#: shifted into it; two senders deliver 2) …
SENSOR_RATE_FACTOR = 1.25
#: … plus this many (a delivery late by a few periods at either end of the window)
SENSOR_RATE_SLACK = 10


class RateWindow:
    """Frames counted per control period over the last ``window`` periods (a ring indexed by
    the loop's cycle number, so skipped periods count as periods with no frame)."""

    __slots__ = ("_counts", "_cycle", "total")

    def __init__(self, window: int = SENSOR_RATE_WINDOW_CYCLES) -> None:
        self._counts = [0] * window
        self._cycle = 0  # the newest cycle the ring holds
        self.total = 0  # frames in the window

    def add(self, cycle: int) -> None:
        """One frame in the loop's cycle ``cycle`` (never earlier than the previous one)."""
        n = len(self._counts)
        if cycle > self._cycle:
            if cycle - self._cycle >= n:
                self._counts = [0] * n
                self.total = 0
            else:
                for c in range(self._cycle + 1, cycle + 1):
                    self.total -= self._counts[c % n]
                    self._counts[c % n] = 0
            self._cycle = cycle
        self._counts[cycle % n] += 1
        self.total += 1

    def __len__(self) -> int:
        """The window (periods)."""
        return len(self._counts)

    def bound(self) -> float:
        """The most frames one sensor at one frame per period delivers in the window."""
        return SENSOR_RATE_FACTOR * len(self._counts) + SENSOR_RATE_SLACK
