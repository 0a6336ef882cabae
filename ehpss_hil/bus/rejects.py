"""Datagrams on the ``udp_multicast`` group that are not a frame: counted, never raised.

Anyone on the host (in the namespace) can send a datagram to the bus's group and port: an empty
one, text, any msgpack value, one larger than the receive buffer. :class:`DatagramRejects` counts
them by reason for :mod:`ehpss_hil.bus.udp`'s readers and warns without flooding the log.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import msgpack

log = logging.getLogger(__name__)

#: at most this many bad datagrams are skipped in one read call before it returns "nothing"
#: (a flood of garbage cannot hold a loop inside one read)
MAX_REJECTS_PER_READ = 1000


class DatagramRejects:
    """Datagrams that are not a frame this bus can take, counted by reason, never raised.

    Reasons: ``empty``, ``oversize`` (longer than the receive buffer: cut by the kernel),
    ``not msgpack``, ``not a frame`` (msgpack, but not python-can's frame map) and ``CAN FD`` (on
    a classic-CAN bus). The first is warned about at once, later ones at most every
    :attr:`WARN_INTERVAL_S` seconds with the running count (the real-time loop is not flooded).
    """

    WARN_INTERVAL_S = 10.0

    def __init__(self, where: str = "udp_multicast") -> None:
        self.where = where
        self.total = 0
        self.by_reason: dict[str, int] = {}
        self._next_warn_s = 0.0

    def add(self, reason: str) -> None:
        """Count one rejected datagram (and warn when due)."""
        self.total += 1
        self.by_reason[reason] = self.by_reason.get(reason, 0) + 1
        now = time.monotonic()
        if now >= self._next_warn_s:
            self._next_warn_s = now + self.WARN_INTERVAL_S
            log.warning(
                "%s: %d datagram(s) rejected so far, not CAN frames (%s); skipped",
                self.where,
                self.total,
                self.text(),
            )

    def text(self) -> str:
        """``3 (empty 1, not msgpack 2)`` style counts."""
        return ", ".join(f"{k} {n}" for k, n in sorted(self.by_reason.items())) or "none"

    def as_dict(self) -> dict[str, Any]:
        """``{"total": n, "by_reason": {...}}`` (JSON-able)."""
        return {"total": self.total, "by_reason": dict(sorted(self.by_reason.items()))}


def reject_reason(data: bytes, buffer_bytes: int) -> str:
    """Why ``data`` (a datagram that did not unpack into a frame) was rejected."""
    if not data:
        return "empty"
    if len(data) >= buffer_bytes:
        return "oversize"
    try:
        msgpack.unpackb(data, raw=False)
    except Exception:  # msgpack raises ValueError subclasses, TypeError, StackError, …
        return "not msgpack"
    return "not a frame"
