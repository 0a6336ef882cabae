"""The campaign's progress line on stderr: runs done, share, runs/s and ETA.

On a terminal one line is rewritten in place (at most every :data:`TTY_PERIOD_S`); otherwise a
line is printed at most every :data:`LOG_PERIOD_S`, so a log file stays short.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

#: least time between two redraws of the line on a terminal (s)
TTY_PERIOD_S = 0.2
#: least time between two progress lines into a file or pipe (s)
LOG_PERIOD_S = 10.0


def format_eta(seconds: float) -> str:
    """``1h02m``, ``3m07s`` or ``12s``."""
    s = round(seconds)
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    if s >= 60:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s}s"


class Progress:
    """Counts finished runs of ``total`` (``already`` of them finished before this session)."""

    def __init__(self, total: int, already: int = 0, stream: TextIO | None = None) -> None:
        self.total, self.done, self.already = total, already, already
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.t0 = time.monotonic()
        self._last = -1e9
        self._drawn = -1

    def line(self) -> str:
        """The progress text now."""
        new = self.done - self.already
        elapsed = time.monotonic() - self.t0
        rate = new / elapsed if elapsed > 0 else 0.0
        left = self.total - self.done
        eta = format_eta(left / rate) if rate > 0 else "?"
        pct = 100.0 * self.done / self.total if self.total else 100.0
        return f"campaign: {self.done}/{self.total} runs ({pct:.1f} %), {rate:.2f} runs/s, ETA {eta}"

    def step(self, n: int = 1) -> None:
        """``n`` more runs finished; redraw when due."""
        self.done += n
        now = time.monotonic()
        if now - self._last >= (TTY_PERIOD_S if self.tty else LOG_PERIOD_S) or self.done == self.total:
            self._last = now
            self._draw()

    def _draw(self) -> None:
        self._drawn = self.done
        if self.tty:
            self.stream.write("\r" + self.line() + "\x1b[K")
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def finish(self) -> None:
        """End the line (a newline after the terminal's last redraw)."""
        if self._drawn != self.done:
            self._draw()
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
