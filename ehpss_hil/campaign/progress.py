"""The campaign's progress line on stderr: runs done, share, runs/s, ETA, and the workers lost
and runs retried when there are any.

On a terminal one line is rewritten in place (at most every :data:`TTY_PERIOD_S`). Into a file
or a pipe (a log, CI) a line is printed each time another :data:`LOG_SHARE` of the runs is done
or :data:`LOG_PERIOD_S` have passed, whichever comes first, and at once when a worker is lost
or a run retried: about ten lines for a campaign, however long it takes.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import TextIO

from .workers import Tally

#: least time between two redraws of the line on a terminal (s)
TTY_PERIOD_S = 0.2
#: off a terminal: a line each time this share of the runs is done …
LOG_SHARE = 0.10
#: … or this long after the last line, whichever comes first (s)
LOG_PERIOD_S = 30.0


def format_eta(seconds: float) -> str:
    """``1h02m``, ``3m07s`` or ``12s``."""
    s = round(seconds)
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    if s >= 60:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s}s"


class Progress:
    """Counts finished runs of ``total`` (``already`` of them finished before this session);
    ``tally`` (set by the session) holds the workers lost and runs retried; ``clock`` gives
    the time in seconds."""

    def __init__(
        self,
        total: int,
        already: int = 0,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.total, self.done, self.already = total, already, already
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.tally = Tally()
        self.clock = clock
        self.t0 = clock()
        self._last = self.t0
        self._drawn = -1
        self._drawn_share = self._share()
        self._drawn_tally = (0, 0)

    def line(self) -> str:
        """The progress text now."""
        new = self.done - self.already
        elapsed = self.clock() - self.t0
        rate = new / elapsed if elapsed > 0 else 0.0
        left = self.total - self.done
        eta = format_eta(left / rate) if rate > 0 else "?"
        pct = 100.0 * self.done / self.total if self.total else 100.0
        trouble = self.tally.text()
        return f"campaign: {self.done}/{self.total} runs ({pct:.1f} %), {rate:.2f} runs/s, ETA {eta}" + (
            f", {trouble}" if trouble else ""
        )

    def _share(self) -> int:
        """How many whole :data:`LOG_SHARE` steps of the runs are done."""
        return math.floor(self.done / self.total / LOG_SHARE + 1e-9) if self.total else 0

    def _due(self, now: float) -> bool:
        if self.done == self.total or self.tally.counts() != self._drawn_tally:
            return True
        if self.tty:
            return now - self._last >= TTY_PERIOD_S
        return self._share() > self._drawn_share or now - self._last >= LOG_PERIOD_S

    def step(self, n: int = 1) -> None:
        """``n`` more runs finished; redraw when due."""
        self.done += n
        now = self.clock()
        if self._due(now):
            self._last = now
            self._draw()

    def _draw(self) -> None:
        self._drawn = self.done
        self._drawn_share = self._share()
        self._drawn_tally = self.tally.counts()
        if self.tty:
            self.stream.write("\r" + self.line() + "\x1b[K")
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def finish(self) -> None:
        """End the line (a newline after the terminal's last redraw)."""
        if self._drawn != self.done or self.tally.counts() != self._drawn_tally:
            self._draw()
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
