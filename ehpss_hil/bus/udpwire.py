"""python-can's ``udp_multicast`` datagram as templates: a frame of a known shape (ID, flags,
DLC) is ``head + float64 timestamp + middle + data + tail`` of python-can's own ``pack_message``.

:func:`template` finds a shape's three parts (and checks that splicing reproduces
``pack_message`` byte for byte); :class:`DatagramParser` reads the frames of known shapes off
their templates and everything else through python-can's ``unpack_message``. Used by the
readers and the writer of :mod:`ehpss_hil.bus.udp`; ``tests/test_bus_udp_boundary.py`` pins the
wire format.
"""

from __future__ import annotations

import struct

import can
import msgpack
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

F64 = struct.Struct(">d")  # msgpack float 64
#: how every python-can datagram starts: fixmap(11), the key "timestamp", the float64 tag
HEAD = b"\x8b" + msgpack.packb("timestamp") + b"\xcb"
AT_MIDDLE = len(HEAD) + 8  # after the timestamp's 8 bytes


class DatagramParser:
    """python-can's ``unpack_message(data, replace={"timestamp": ts}, check=True)``, with the
    frame shapes already seen read off their templates (:func:`template`) instead.

    A datagram that is exactly ``head + any 8 bytes + middle + n bytes + tail`` of a known shape
    is what ``pack_message`` makes of a frame of that shape with those data bytes, so the
    :class:`can.Message` is built from the shape without decoding the map and re-checking it.
    Everything else goes through ``unpack_message``; its plain shapes (standard/extended data
    frames, no channel) are learnt, at most :attr:`MAX_SHAPES` of them (a fuzzer's random IDs
    cannot grow the table without bound)."""

    MAX_SHAPES = 64

    def __init__(self) -> None:
        #: per middle length: middle → (ID, extended, DLC, data length, tail)
        self._by_len: dict[int, dict[bytes, tuple[int, bool, int, int, bytes]]] = {}
        self.shapes = 0

    def parse(self, data: bytes, timestamp_s: float) -> can.Message:
        """The frame in ``data`` with ``timestamp_s``; CanOperationError when it is none."""
        if data.startswith(HEAD):
            for mlen, table in self._by_len.items():
                hit = table.get(data[AT_MIDDLE : AT_MIDDLE + mlen])
                if hit is None:
                    continue
                can_id, ext, dlc, n, tail = hit
                at = AT_MIDDLE + mlen
                if len(data) == at + n + len(tail) and data.endswith(tail):
                    return can.Message(
                        timestamp=timestamp_s,
                        arbitration_id=can_id,
                        is_extended_id=ext,
                        dlc=dlc,
                        data=data[at : at + n],
                        check=False,
                    )
        try:
            msg = unpack_message(data, replace={"timestamp": timestamp_s}, check=True)
        except Exception as exc:
            raise can.CanOperationError("could not unpack received message") from exc
        self.learn(msg)
        return msg

    def learn(self, msg: can.Message) -> None:
        """Add ``msg``'s shape (a plain data frame; up to :attr:`MAX_SHAPES` shapes)."""
        if self.shapes >= self.MAX_SHAPES:
            return
        if (
            msg.is_fd
            or msg.is_remote_frame
            or msg.is_error_frame
            or msg.channel is not None
            or msg.bitrate_switch
            or msg.error_state_indicator
            or msg.dlc != len(msg.data)
        ):
            return
        tpl = template(msg)
        if tpl is None:
            return
        _, middle, tail = tpl
        table = self._by_len.setdefault(len(middle), {})
        if middle not in table:
            table[middle] = (msg.arbitration_id, msg.is_extended_id, msg.dlc, len(msg.data), tail)
            self.shapes += 1


def template(msg: can.Message) -> tuple[bytes, bytes, bytes] | None:
    """(head, middle, tail) of ``msg``'s shape: ``pack_message`` of any frame of that shape is
    ``head + float64 timestamp + middle + data + tail``; None when splicing does not give
    ``pack_message``'s bytes for two different probes (a python-can that packs otherwise)."""
    n = len(msg.data)

    def probe(ts: float, data: bytes) -> can.Message:
        return can.Message(
            timestamp=ts,
            arbitration_id=msg.arbitration_id,
            is_extended_id=msg.is_extended_id,
            is_remote_frame=msg.is_remote_frame,
            is_error_frame=msg.is_error_frame,
            channel=msg.channel,
            dlc=msg.dlc,
            data=data,
            is_fd=msg.is_fd,
            bitrate_switch=msg.bitrate_switch,
            error_state_indicator=msg.error_state_indicator,
            check=False,
        )

    data_key = msgpack.packb("data") + msgpack.packb(bytes(n))[: -n or None]
    first = pack_message(probe(1.5, bytes(n)))
    at = first.find(data_key, AT_MIDDLE)
    if not first.startswith(HEAD) or at < 0 or first.find(data_key, at + 1) >= 0:
        return None
    middle = first[AT_MIDDLE : at + len(data_key)]
    tail = first[at + len(data_key) + n :]
    for ts, data in ((1.5, bytes(n)), (1779999999.123456, bytes(range(1, n + 1)))):
        if pack_message(probe(ts, data)) != b"".join((HEAD, F64.pack(ts), middle, data, tail)):
            return None
    return HEAD, middle, tail
