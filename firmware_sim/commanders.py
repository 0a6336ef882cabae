"""A second transmitter of VALVE_CMD: detected from the sequence of the frames that pass E2E.

One controller sends one VALVE_CMD per cycle with its CycleCount advancing by one (more after an
overrun it catches up on). A second node on the same ID — a rogue transmitter, a second
controller, a replayed log — interleaves a CycleCount sequence of its own, and its E2E counter
interleaves with ours: some of its frames fail the E2E counter check (REPEATED, WRONG_SEQUENCE),
the others arrive out of CycleCount order. Both are counted here as foreign; a conflict is
declared when a window of recent frames holds ``limit`` foreign ones and ends when a whole window
holds none. While it lasts the emulator centres the valve (0 A), as on a command timeout: it
cannot tell which commander is the real one, and obeying both drove the piston 430 mm away.

A single commander may also jump: a controller stopped for seconds (SIGSTOP, a hog) resumes with
its CycleCount thousands ahead (and catching up on its backlog, it may send only every ~20th
cycle for a while). The frame right after an out-of-order one that follows it in order
resynchronizes the check on it, as the E2E counter check does; interleaved senders alternate
and so keep counting as foreign.
"""

from __future__ import annotations

from collections import deque

#: CycleCount is 16 bits
CYCLE_MODULUS = 1 << 16


class CommanderCheck:
    """Conflict detector over the last ``window`` VALVE_CMD frames (usable or E2E-rejected)."""

    __slots__ = (
        "_advancing",
        "_candidate",
        "_foreign_in_window",
        "_last",
        "_limit",
        "_max_ahead",
        "_recent",
        "conflict",
        "conflicts",
        "foreign",
    )

    def __init__(self, window: int, limit: int, max_ahead: int) -> None:
        """``window``: frames looked back over; ``limit``: foreign frames in it that make a
        conflict; ``max_ahead``: the largest CycleCount step one controller makes (its catch-up
        after a stall), larger steps and any step back are out of order."""
        self._limit = max(1, limit)
        self._max_ahead = max_ahead
        self._recent: deque[bool] = deque(maxlen=max(window, self._limit))
        self._foreign_in_window = 0
        self._last: int | None = None
        self._candidate: int | None = None  # the CycleCount of the last out-of-order frame
        self._advancing = False  # the CycleCount has moved on in order at least once
        self.conflict = False
        self.conflicts = 0  # conflicts declared
        self.foreign = 0  # frames counted as foreign

    def usable(self, cycle_count: int) -> bool:
        """A VALVE_CMD that passed E2E with this CycleCount; returns True when in order. Until the
        CycleCount has once advanced in order (a commander that leaves it 0) it is no evidence."""
        last = self._last
        if last is None:
            self._last = cycle_count
            ok = True
        else:
            step = (cycle_count - last) % CYCLE_MODULUS
            ok = 1 <= step <= self._max_ahead
            if ok:
                self._last = cycle_count
                self._advancing = True
            elif not self._advancing:  # a sender that does not count cycles: no evidence
                self._last, ok = cycle_count, True
            elif (
                self._candidate is not None
                and 0 < step < CYCLE_MODULUS // 2
                and 1 <= (cycle_count - self._candidate) % CYCLE_MODULUS <= self._max_ahead
            ):
                self._last, ok = cycle_count, True  # one commander that jumped ahead: resync
        self._candidate = None if ok else cycle_count
        self._push(not ok)
        return ok

    def rejected_sequence(self) -> None:
        """A VALVE_CMD whose E2E counter was REPEATED or WRONG_SEQUENCE."""
        self._candidate = None
        self._push(True)

    def _push(self, foreign: bool) -> None:
        r = self._recent
        if len(r) == r.maxlen and r[0]:
            self._foreign_in_window -= 1
        r.append(foreign)
        if foreign:
            self.foreign += 1
            self._foreign_in_window += 1
        if not self.conflict and self._foreign_in_window >= self._limit:
            self.conflict = True
            self.conflicts += 1
        elif self.conflict and self._foreign_in_window == 0:
            self.conflict = False
