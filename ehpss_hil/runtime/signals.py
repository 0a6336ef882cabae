"""SIGTERM/SIGINT → a stop flag the loop polls once per cycle (no work in the handler)."""

from __future__ import annotations

import signal
from types import FrameType
from typing import Any


class StopFlag:
    """Set by a signal (or by code); the loop ends at its next check. ``bool(flag)`` = stop."""

    __slots__ = ("signum", "stop")

    def __init__(self) -> None:
        self.stop = False
        self.signum: int | None = None

    def set(self, signum: int | None = None) -> None:
        """Request the loop to stop."""
        self.stop = True
        self.signum = signum

    def __bool__(self) -> bool:
        return self.stop


def install_stop_handlers(
    flag: StopFlag | None = None, signals: tuple[int, ...] = (signal.SIGTERM, signal.SIGINT)
) -> tuple[StopFlag, dict[int, Any]]:
    """Route ``signals`` to ``flag.set``; returns the flag and the previous handlers.

    Must be called from the main thread.
    """
    f = flag if flag is not None else StopFlag()

    def _handler(signum: int, frame: FrameType | None) -> None:
        f.set(signum)

    previous = {s: signal.signal(s, _handler) for s in signals}
    return f, previous


def restore_handlers(previous: dict[int, Any]) -> None:
    """Put back the handlers :func:`install_stop_handlers` replaced."""
    for s, h in previous.items():
        signal.signal(s, h)
