"""python-can ``udp_multicast`` at the cost a 1 kHz loop can afford.

Three things python-can's generic path does per frame that a loop draining the bus every cycle
does not need:

- ``bus.recv(0.0)`` calls ``select()`` before every ``recvmsg()``: two system calls per frame
  and one more to learn that nothing is left. :class:`UdpReader` reads the socket directly with
  ``MSG_DONTWAIT`` and otherwise does what python-can's ``UdpMulticastBus._recv_internal``
  does: the kernel receive timestamp (``SO_TIMESTAMPNS``), ``unpack_message(check=True)``, the
  same errors; a frame of a shape already seen is read off that shape's template
  (:class:`DatagramParser`) instead of decoding the msgpack map into a dict and re-checking it.
  (One difference: python-can's ``recv`` treats a frame with DLC 0 as "no frame" — ``if msg``
  on a Message is its length — and drops it unlogged; here it is returned.)
- The socket loops every frame back to its sender, so a process receives all its own frames
  and drops them after decoding. :func:`attach_own_id_filter` installs a classic BPF socket
  filter that drops them in the kernel. It matches the msgpack layout python-can's
  ``pack_message`` produces (a map whose first keys are ``timestamp`` as float64 and
  ``arbitration_id``); a datagram that does not start that way is accepted, so the filter can
  only ever drop the listed IDs, and :class:`~ehpss_hil.runtime.frameio.FrameIO` still drops
  own IDs itself.
- ``bus.send`` packs every frame through a fresh dict and ``msgpack.packb``. A loop sends the
  same few frame shapes, whose datagrams differ only in the timestamp and the data bytes:
  :class:`UdpWriter` builds each shape's datagram once with python-can's own ``pack_message``,
  checks that splicing a timestamp and data into it reproduces ``pack_message`` exactly, and
  then writes ``head + timestamp + middle + data + tail`` to the same socket and destination
  (anything else goes through ``bus.send``).

Anyone on the host (in the namespace) can send a datagram to the group and port. python-can
raises ``CanOperationError`` for one that is not a frame, which would end every process on the
bus; here such a datagram is counted in :class:`DatagramRejects` and skipped, on both read paths
(:class:`UdpReader` and :class:`GuardedUdpMulticastBus`, which ``open_bus`` makes).
"""

from __future__ import annotations

import ctypes
import socket
import struct
import time
from collections.abc import Iterable
from typing import Any

import can
import msgpack
from can.interfaces.udp_multicast import UdpMulticastBus
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from .udp_rejects import MAX_REJECTS_PER_READ, DatagramRejects, reject_reason

SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_TIMESPEC = struct.Struct("@ll")
_F64 = struct.Struct(">d")  # msgpack float 64
_UDP_HEADER = 8  # a UDP socket filter sees the UDP header first
#: how every python-can datagram starts: fixmap(11), the key "timestamp", the float64 tag
_HEAD = b"\x8b" + msgpack.packb("timestamp") + b"\xcb"
_AT_MIDDLE = len(_HEAD) + 8  # after the timestamp's 8 bytes

# classic BPF opcodes (linux/filter.h)
_LD_W, _LD_H, _LD_B = 0x20, 0x28, 0x30  # BPF_LD | BPF_{W,H,B} | BPF_ABS
_LD_LEN = 0x80  # BPF_LD | BPF_W | BPF_LEN
_JEQ, _JGE = 0x15, 0x35  # BPF_JMP | BPF_{JEQ,JGE} | BPF_K
_RET = 0x06  # BPF_RET | BPF_K
_ACCEPT, _DROP = 0xFFFFFFFF, 0

class UdpReader:
    """Non-blocking reads from a python-can ``UdpMulticastBus`` without ``select()``."""

    def __init__(self, bus: can.BusABC) -> None:
        mc = bus._multicast  # type: ignore[attr-defined]
        self._bus = bus
        self._sock: socket.socket = mc._socket
        self._max = int(mc.max_buffer)
        self._anc = int(mc.received_ancillary_buffer_size)
        self._fd = bus.protocol is can.CanProtocol.CAN_FD
        self._parser = DatagramParser()
        #: the bus's own counter when it has one (both read paths count in one place)
        self.rejects = bus.rejects if isinstance(bus, GuardedUdpMulticastBus) else \
            DatagramRejects()

    @staticmethod
    def supports(bus: can.BusABC) -> bool:
        """True for a udp_multicast bus with kernel timestamps (Linux)."""
        mc = getattr(bus, "_multicast", None)
        return (isinstance(bus, UdpMulticastBus) and mc is not None
                and getattr(mc, "timestamp_nanosecond", False) and hasattr(mc, "_socket"))

    def read(self) -> can.Message | None:
        """One pending frame, or None when none is pending (never waits). Datagrams that are no
        frame are counted in :attr:`rejects` and skipped."""
        sock = self._sock
        if sock.gettimeout() is not None:  # a send timeout made recvmsg wait: python-can's path
            return self._bus.recv(0.0)
        for _ in range(MAX_REJECTS_PER_READ):
            try:
                data, anc, flags, _addr = sock.recvmsg(self._max, self._anc, socket.MSG_DONTWAIT)
            except BlockingIOError:
                return None
            msg = self._frame(data, anc, flags)
            if msg is not None:
                return msg
        return None

    def _frame(self, data: bytes, anc: list[tuple[int, int, bytes]],
               flags: int) -> can.Message | None:
        """The frame in one datagram, or None (counted) when it is none."""
        if len(anc) != 1:
            raise can.CanOperationError("Only requested a single extra field but got a "
                                        "different amount")
        level, kind, cdata = anc[0]
        if level != socket.SOL_SOCKET or kind != SO_TIMESTAMPNS:
            raise can.CanOperationError("received control message type that was not requested")
        seconds, nanoseconds = _TIMESPEC.unpack(cdata)
        if nanoseconds >= 1e9:
            raise can.CanOperationError(f"Timestamp nanoseconds field was out of range: "
                                        f"{nanoseconds} not less than 1e9")
        if flags & socket.MSG_TRUNC:
            self.rejects.add("oversize")
            return None
        try:
            msg = self._parser.parse(data, seconds + nanoseconds * 1.0e-9)
        except can.CanOperationError:
            self.rejects.add(reject_reason(data, self._max))
            return None
        if not self._fd and msg.is_fd:
            self.rejects.add("CAN FD")
            return None
        return msg

    def prepare(self, shapes: Iterable[can.Message]) -> None:
        """Learn the templates of ``shapes`` now (a template costs a few ``pack_message`` calls:
        at start-up rather than in a cycle's first frames)."""
        for msg in shapes:
            self._parser.learn(msg)


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
        if data.startswith(_HEAD):
            for mlen, table in self._by_len.items():
                hit = table.get(data[_AT_MIDDLE:_AT_MIDDLE + mlen])
                if hit is None:
                    continue
                can_id, ext, dlc, n, tail = hit
                at = _AT_MIDDLE + mlen
                if len(data) == at + n + len(tail) and data.endswith(tail):
                    return can.Message(timestamp=timestamp_s, arbitration_id=can_id,
                                       is_extended_id=ext, dlc=dlc, data=data[at:at + n],
                                       check=False)
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
        if (msg.is_fd or msg.is_remote_frame or msg.is_error_frame or msg.channel is not None
                or msg.bitrate_switch or msg.error_state_indicator or msg.dlc != len(msg.data)):
            return
        tpl = template(msg)
        if tpl is None:
            return
        _, middle, tail = tpl
        table = self._by_len.setdefault(len(middle), {})
        if middle not in table:
            table[middle] = (msg.arbitration_id, msg.is_extended_id, msg.dlc, len(msg.data), tail)
            self.shapes += 1


class GuardedUdpMulticastBus(UdpMulticastBus):
    """python-can's ``UdpMulticastBus`` whose ``recv`` skips and counts (:attr:`rejects`) a
    datagram that is not a frame instead of raising ``CanOperationError``; socket errors still
    raise. Frames are unpacked by a :class:`DatagramParser` (the same result as python-can's)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.rejects = DatagramRejects()
        self._parser = DatagramParser()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        mc = self._multicast
        for _ in range(MAX_REJECTS_PER_READ):
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            result = mc.recv(left)
            if not result:
                return None, False
            data, _, timestamp = result
            try:
                msg = self._parser.parse(data, timestamp)
            except can.CanOperationError:
                self.rejects.add(reject_reason(data, mc.max_buffer))
                continue
            if self.protocol is not can.CanProtocol.CAN_FD and msg.is_fd:
                self.rejects.add("CAN FD")
                continue
            return msg, False
        return None, False


def template(msg: can.Message) -> tuple[bytes, bytes, bytes] | None:
    """(head, middle, tail) of ``msg``'s shape: ``pack_message`` of any frame of that shape is
    ``head + float64 timestamp + middle + data + tail``; None when splicing does not give
    ``pack_message``'s bytes for two different probes (a python-can that packs otherwise)."""
    n = len(msg.data)

    def probe(ts: float, data: bytes) -> can.Message:
        return can.Message(timestamp=ts, arbitration_id=msg.arbitration_id,
                           is_extended_id=msg.is_extended_id,
                           is_remote_frame=msg.is_remote_frame,
                           is_error_frame=msg.is_error_frame, channel=msg.channel,
                           dlc=msg.dlc, data=data, is_fd=msg.is_fd,
                           bitrate_switch=msg.bitrate_switch,
                           error_state_indicator=msg.error_state_indicator, check=False)

    data_key = msgpack.packb("data") + msgpack.packb(bytes(n))[:-n or None]
    first = pack_message(probe(1.5, bytes(n)))
    at = first.find(data_key, _AT_MIDDLE)
    if not first.startswith(_HEAD) or at < 0 or first.find(data_key, at + 1) >= 0:
        return None
    middle = first[_AT_MIDDLE:at + len(data_key)]
    tail = first[at + len(data_key) + n:]
    for ts, data in ((1.5, bytes(n)), (1779999999.123456, bytes(range(1, n + 1)))):
        if pack_message(probe(ts, data)) != b"".join((_HEAD, _F64.pack(ts), middle, data, tail)):
            return None
    return _HEAD, middle, tail


_Shape = tuple[int, bool, bool, bool, object, int, int, bool, bool, bool]


class UdpWriter:
    """Sends python-can ``udp_multicast`` frames as spliced templates (see the module doc)."""

    def __init__(self, bus: can.BusABC) -> None:
        mc = bus._multicast  # type: ignore[attr-defined]
        self._bus = bus
        self._mc = mc
        self._sock: socket.socket = mc._socket
        self._dest = mc._send_destination
        self._fd = bus.protocol is can.CanProtocol.CAN_FD
        #: shape → (head, middle, tail), or None: that shape goes through ``bus.send``
        self._templates: dict[_Shape, tuple[bytes, bytes, bytes] | None] = {}

    @staticmethod
    def supports(bus: can.BusABC) -> bool:
        """True for a python-can ``UdpMulticastBus`` with the attributes this relies on."""
        mc = getattr(bus, "_multicast", None)
        return (isinstance(bus, UdpMulticastBus) and mc is not None and hasattr(mc, "_socket")
                and hasattr(mc, "_send_destination") and hasattr(mc, "_last_send_timeout"))

    def prepare(self, shapes: Iterable[can.Message]) -> None:
        """Build the templates of ``shapes`` now rather than on their first send."""
        for msg in shapes:
            self._templates.setdefault(self._shape(msg), template(msg))

    @staticmethod
    def _shape(msg: can.Message) -> _Shape:
        return (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame,
                msg.channel, msg.dlc, len(msg.data), msg.is_fd, msg.bitrate_switch,
                msg.error_state_indicator)

    def write(self, msg: can.Message) -> None:
        """Send ``msg`` as ``bus.send(msg)`` would (same datagram, same errors)."""
        if self._mc._last_send_timeout is not None or type(msg.timestamp) is not float:
            self._bus.send(msg)
            return
        data = msg.data
        shape = self._shape(msg)
        try:
            tpl = self._templates[shape]
        except KeyError:
            tpl = self._templates[shape] = template(msg)
        if tpl is None or (msg.is_fd and not self._fd):
            self._bus.send(msg)
            return
        head, middle, tail = tpl
        datagram = b"".join((head, _F64.pack(msg.timestamp), middle, data, tail))
        try:
            sent = self._sock.sendto(datagram, self._dest)
        except TimeoutError:
            raise can.CanTimeoutError() from None
        except OSError as error:
            raise can.CanOperationError("failed to send via socket") from error
        if sent < len(datagram):
            raise can.CanTimeoutError()


def _expect(offset: int, data: bytes, fail: str) -> list[tuple[int, int | str, int]]:
    """Loads and compares (4, 2, then 1 byte at a time) that jump to ``fail`` on a mismatch
    (the packet is known to be long enough)."""
    out: list[tuple[int, int | str, int]] = []
    i = 0
    while i < len(data):
        n = 4 if len(data) - i >= 4 else 2 if len(data) - i >= 2 else 1
        op = {4: _LD_W, 2: _LD_H, 1: _LD_B}[n]
        out.append((op, 0, offset + i))
        out.append((_JEQ, fail, int.from_bytes(data[i:i + n], "big")))
        i += n
    return out


def own_id_program(can_ids: Iterable[int]) -> list[tuple[int, int, int, int]] | None:
    """The BPF program (code, jt, jf, k) dropping python-can datagrams of ``can_ids``, or None
    when python-can's packing is not the layout it relies on (then nothing is filtered)."""
    key = msgpack.packb("arbitration_id")
    at_key = _AT_MIDDLE
    at_id = at_key + len(key)
    ids = sorted(set(can_ids))
    blocks: list[tuple[list[tuple[int, int | str, int]], str]] = []
    for i, can_id in enumerate(ids):
        enc = msgpack.packb(can_id)
        probe = pack_message(can.Message(arbitration_id=can_id, timestamp=1.5,
                                         is_extended_id=can_id > 0x7FF))
        if not (probe.startswith(_HEAD) and probe[at_key:at_id] == key
                and probe[at_id:at_id + len(enc)] == enc):
            return None
        blocks.append((_expect(_UDP_HEADER + at_id, enc, f"next{i}"), f"next{i}"))
    if not blocks:
        return None
    longest = max(len(msgpack.packb(i)) for i in ids)
    # a shorter datagram is accepted (a load beyond the packet would make the kernel drop it)
    code: list[tuple[int, int | str, int]] = [(_LD_LEN, 0, 0),
                                              (_JGE, "accept", _UDP_HEADER + at_id + longest)]
    code += _expect(_UDP_HEADER, _HEAD, "accept")
    code += _expect(_UDP_HEADER + at_key, key, "accept")
    labels: dict[str, int] = {}
    for checks, label in blocks:
        code += checks
        code.append((_RET, 0, _DROP))
        labels[label] = len(code)
    labels["accept"] = len(code)
    code.append((_RET, 0, _ACCEPT))
    prog = []
    for pc, (op, jf, k) in enumerate(code):
        off = labels[jf] - pc - 1 if isinstance(jf, str) else 0
        if not 0 <= off <= 255:
            return None
        prog.append((op, 0, off, k))  # JEQ/JGE: true → next instruction, false → jump
    return prog


def attach_own_id_filter(bus: can.BusABC, can_ids: Iterable[int]) -> bool:
    """Drop datagrams carrying ``can_ids`` in the kernel (SO_ATTACH_FILTER); True when attached."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    prog = own_id_program(can_ids)
    if sock is None or prog is None:
        return False
    buf = ctypes.create_string_buffer(b"".join(struct.pack("HBBI", *ins) for ins in prog))
    try:  # struct sock_fprog {unsigned short len; struct sock_filter *filter;}; copied by the kernel
        sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER,
                        struct.pack("HL", len(prog), ctypes.addressof(buf)))
    except OSError:
        return False
    return True
