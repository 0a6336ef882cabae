"""Raw frame I/O at the edge of a loop for protocols without a DBC (CANopen): send and log by
COB-ID, drain without blocking. The frame-codec counterpart is :mod:`.frameio`.

Each frame is logged exactly once, when sent or when received. Where the bus may hand the
process its own frames back (:func:`~ehpss_hil.bus.suppress_own_echoes` False), frames received
on an ID this process sends are dropped unlogged: a CANopen node never consumes its own COB-IDs.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Iterator

import can

from ..bus import datagram_rejects, frame_reader, frame_writer, suppress_own_echoes
from .frameio import FrameLogger

log = logging.getLogger(__name__)


class RawFrameIO:
    """One process's raw frames on ``bus``; counts sent frames per COB-ID and transmit errors."""

    def __init__(self, bus: can.BusABC, logger: FrameLogger | None = None) -> None:
        self.bus = bus
        self.logger = logger
        self.echoes_suppressed = suppress_own_echoes(bus)
        self._read = frame_reader(bus)
        self._write = frame_writer(bus)
        self.sent: Counter[int] = Counter()
        self.received = 0
        self.tx_errors = 0

    def send(self, can_id: int, data: bytes) -> bool:
        """Send and log one classic 11-bit frame; False when the bus refused it (counted)."""
        msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=False, timestamp=time.time())
        try:
            self._write(msg)
        except (can.CanError, OSError) as exc:
            self.tx_errors += 1
            if self.tx_errors == 1 or self.tx_errors % 1000 == 0:
                log.warning("0x%03X not sent (%d transmit errors): %s", can_id, self.tx_errors, exc)
            return False
        self.sent[can_id] += 1
        if self.logger is not None:
            self.logger.log(msg)
        return True

    def drain(self, limit: int = 1000) -> Iterator[can.Message]:
        """Every frame pending now (non-blocking), at most ``limit`` read; own echoes dropped."""
        for _ in range(limit):
            msg = self._read()
            if msg is None:
                return
            if not self.echoes_suppressed and msg.arbitration_id in self.sent:
                continue
            self.received += 1
            if self.logger is not None:
                self.logger.log(msg)
            yield msg

    def idle(self) -> None:
        """The cycle is done: the log writer may run now."""
        if self.logger is not None:
            self.logger.kick()

    def close(self) -> None:
        """Flush/close the log (the bus is closed by its owner)."""
        if self.logger is not None:
            rejects = datagram_rejects(self.bus)
            self.logger.note("rejected_datagrams", rejects.as_dict() if rejects is not None else {"total": 0})
            self.logger.close()
            self.logger = None
