"""Reading a node's error history (0x1003) by SDO without blocking the loop.

After an EMCY the master asks the node for its error history: an SDO expedited upload of
0x1003.0 (the number of errors), then of each sub-index 1…n (newest first). Each request is a
frame the loop sends after its command (:meth:`ErrorHistoryReader.take_request`) and each answer
a frame it drains (:meth:`ErrorHistoryReader.on_response`); nothing waits. An abort or a new read
ends the one in progress. Pure: no bus, no clock.
"""

from __future__ import annotations

import struct

import can

from . import cobid
from .cyclic import frame
from .objects import ERROR_HISTORY

#: SDO command specifiers (CiA 301): initiate upload request; expedited upload response (any
#: size: bits 0…3 are size and flags); abort
SDO_UPLOAD_REQUEST = 0x40
SDO_UPLOAD_RESPONSE = 0x40
SDO_COMMAND_MASK = 0xE0
SDO_ABORT = 0x80
#: the error history read back at most (sub-indices 1…)
MAX_ERRORS = 8


class ErrorHistoryReader:
    """One node's error history, read after each EMCY (the last read's result in :attr:`codes`)."""

    def __init__(self) -> None:
        self.node = 0
        #: the EMCY error codes of the last completed read, newest first
        self.codes: list[int] = []
        self.reads = 0  # completed reads
        self._sub: int | None = None  # the sub-index asked for (None: idle)
        self._count = 0
        self._got: list[int] = []
        self._request: can.Message | None = None

    def start(self, node: int) -> None:
        """Read ``node``'s history from the start (a read in progress is dropped)."""
        self.node, self._got, self._count = node, [], 0
        self._ask(0)

    def _ask(self, sub: int) -> None:
        self._sub = sub
        data = struct.pack("<BHB4x", SDO_UPLOAD_REQUEST, ERROR_HISTORY, sub)
        self._request = frame(cobid.SDO_RX + self.node, data)

    def take_request(self) -> can.Message | None:
        """The request to send now (once), or None."""
        req, self._request = self._request, None
        return req

    def on_response(self, can_id: int, data: bytes) -> bool:
        """An SDO answer frame; True when it was the one awaited (and the read moved on)."""
        if self._sub is None or can_id != cobid.SDO_TX + self.node or len(data) < 8:
            return False
        cmd, index, sub = struct.unpack_from("<BHB", data)
        if index != ERROR_HISTORY or sub != self._sub:
            return False
        if cmd == SDO_ABORT or cmd & SDO_COMMAND_MASK != SDO_UPLOAD_RESPONSE:
            self._sub = None
            return True
        value = struct.unpack_from("<I", data, 4)[0]
        if sub == 0:
            self._count = min(int(value) & 0xFF, MAX_ERRORS)
        else:
            self._got.append(int(value) & 0xFFFF)
        if sub < self._count:
            self._ask(sub + 1)
        else:
            self._sub = None
            self.codes = self._got
            self.reads += 1
        return True

    @property
    def done(self) -> bool:
        """No read in progress."""
        return self._sub is None
