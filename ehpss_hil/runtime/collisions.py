"""ID collisions: frames received on a process's own TX IDs that it did not send.

On a CAN bus each ID has one transmitter; a CAN controller never receives the frames it sent, so
a frame on one of its own TX IDs comes from another node — a second controller, a rogue node, a
replayed log. :class:`IdCollisions` counts them per frame name and warns (the first on each ID
at once, then at most one line of counts every :attr:`IdCollisions.WARN_INTERVAL_S`).

Where the bus does hand a process its own frames back (:func:`~ehpss_hil.bus.suppress_own_echoes`
returned False), :class:`SentFrames` remembers the (ID, data) of the frames sent whose echo has
not come back yet; a received frame equal to one of them is taken as that echo. Frames with an
E2E counter and CRC differ from one another, so this tells a foreign frame from an echo unless
it repeats one of our own recent frames byte for byte (a replay, or a heartbeat, which carries
no counter).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable

log = logging.getLogger(__name__)


class SentFrames:
    """The frames sent whose echo is still due, at most ``capacity`` (the oldest forgotten: its
    echo was lost, e.g. in a receive buffer overflow)."""

    __slots__ = ("_order", "_order_max", "_pending")

    def __init__(self, capacity: int = 4096) -> None:
        self._pending: dict[tuple[int, bytes], int] = {}
        self._order: deque[tuple[int, bytes]] = deque()
        self._order_max = max(1, capacity)

    def add(self, can_id: int, data: bytes | bytearray) -> None:
        """A frame was sent: its echo is due."""
        key = (can_id, bytes(data))
        self._pending[key] = self._pending.get(key, 0) + 1
        self._order.append(key)
        if len(self._order) > self._order_max:
            self._forget(self._order.popleft())

    def take(self, can_id: int, data: bytes | bytearray) -> bool:
        """True (and the echo no longer due) when a frame equal to this one was sent."""
        key = (can_id, bytes(data))
        n = self._pending.get(key, 0)
        if not n:
            return False
        self._forget(key)
        return True

    def _forget(self, key: tuple[int, bytes]) -> None:
        n = self._pending.get(key, 0)
        if n > 1:
            self._pending[key] = n - 1
        elif n:
            del self._pending[key]

    def __len__(self) -> int:
        return sum(self._pending.values())


class IdCollisions:
    """Foreign frames on the own TX IDs (``names_by_id``: CAN ID → frame name), per name."""

    #: after the first warning on an ID, a line of the counts at most this often (s)
    WARN_INTERVAL_S = 10.0

    def __init__(self, names_by_id: dict[int, str], clock: Callable[[], float] = time.monotonic) -> None:
        self._names = dict(names_by_id)
        self.by_name: dict[str, int] = {n: 0 for n in self._names.values()}
        self.total = 0
        self._clock = clock
        self._next_warn_s = 0.0
        self._unwarned = 0

    def add(self, can_id: int) -> None:
        """Count one frame received on ``can_id`` that this process did not send."""
        name = self._names.get(can_id, f"0x{can_id:X}")
        n = self.by_name.get(name, 0) + 1
        self.by_name[name] = n
        self.total += 1
        self._unwarned += 1
        now = self._clock()
        if n == 1 or now >= self._next_warn_s:
            log.warning(
                "ID collision: %s (0x%03X) received from another transmitter; foreign "
                "frames on own IDs: %s (%d since the last warning)",
                name,
                can_id,
                self.text(),
                self._unwarned,
            )
            self._next_warn_s = now + self.WARN_INTERVAL_S
            self._unwarned = 0

    def text(self) -> str:
        """``NAME n, ...`` of the IDs that collided (``none``)."""
        return ", ".join(f"{k} {v}" for k, v in self.by_name.items() if v) or "none"
