"""python-can ``udp_multicast`` at the cost a 1 kHz loop can afford.

Three things python-can's generic path does per frame that a loop draining the bus every cycle
does not need:

- ``bus.recv(0.0)`` calls ``select()`` before every ``recvmsg()``: two system calls per frame
  and one more to learn that nothing is left. :class:`UdpReader` reads the socket directly with
  ``MSG_DONTWAIT`` and otherwise does what python-can's ``UdpMulticastBus._recv_internal``
  does: the kernel receive timestamp (``SO_TIMESTAMPNS``), ``unpack_message(check=True)``, the
  same errors; a frame of a shape already seen is read off that shape's template
  (:class:`~ehpss_hil.bus.udpwire.DatagramParser`) instead of decoding the msgpack map into a
  dict and re-checking it.
  (One difference: python-can's ``recv`` treats a frame with DLC 0 as "no frame" — ``if msg``
  on a Message is its length — and drops it unlogged; here it is returned.)
- The socket loops every frame back to its sender, so a process receives all its own frames.
  Every process binds the group's port, so the datagrams of all of them come from that port:
  :class:`GuardedUdpMulticastBus` sends from a socket of its own instead (an ephemeral port,
  the same hop limit), whose port tells this process's datagrams from every other sender's, and
  :func:`attach_own_source_filter` installs a classic BPF socket filter on the receiving socket
  that drops the datagrams from that port in the kernel (no read, no decoding). A frame on one of
  the process's own IDs that does reach it was sent by another node (an ID collision, which
  :class:`~ehpss_hil.runtime.frameio.FrameIO` counts).
- ``bus.send`` packs every frame through a fresh dict and ``msgpack.packb``. A loop sends the
  same few frame shapes, whose datagrams differ only in the timestamp and the data bytes:
  :class:`UdpWriter` builds each shape's datagram once with python-can's own ``pack_message``,
  checks that splicing a timestamp and data into it reproduces ``pack_message`` exactly, and
  then writes ``head + timestamp + middle + data + tail`` to the bus's sending socket and the
  group (anything else goes through ``bus.send``).

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
from can.interfaces.udp_multicast import UdpMulticastBus
from can.interfaces.udp_multicast.utils import pack_message

from .rejects import MAX_REJECTS_PER_READ, DatagramRejects, reject_reason
from .udpwire import F64, DatagramParser, template

SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_TIMESPEC = struct.Struct("@ll")

# classic BPF opcodes (linux/filter.h)
_LD_H = 0x28  # BPF_LD | BPF_H | BPF_ABS
_JEQ = 0x15  # BPF_JMP | BPF_JEQ | BPF_K
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
        self.rejects = bus.rejects if isinstance(bus, GuardedUdpMulticastBus) else DatagramRejects()

    @staticmethod
    def supports(bus: can.BusABC) -> bool:
        """True for a udp_multicast bus with kernel timestamps (Linux)."""
        mc = getattr(bus, "_multicast", None)
        return (
            isinstance(bus, UdpMulticastBus)
            and mc is not None
            and getattr(mc, "timestamp_nanosecond", False)
            and hasattr(mc, "_socket")
        )

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

    def _frame(self, data: bytes, anc: list[tuple[int, int, bytes]], flags: int) -> can.Message | None:
        """The frame in one datagram, or None (counted) when it is none."""
        if len(anc) != 1:
            raise can.CanOperationError("Only requested a single extra field but got a different amount")
        level, kind, cdata = anc[0]
        if level != socket.SOL_SOCKET or kind != SO_TIMESTAMPNS:
            raise can.CanOperationError("received control message type that was not requested")
        seconds, nanoseconds = _TIMESPEC.unpack(cdata)
        if nanoseconds >= 1e9:
            raise can.CanOperationError(
                f"Timestamp nanoseconds field was out of range: {nanoseconds} not less than 1e9"
            )
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


class UdpTransmitter:
    """The sending socket of one :class:`GuardedUdpMulticastBus`: not bound to the group's port
    (every receiver is) but to an ephemeral one, :attr:`port`, which no other sender on the host
    has; otherwise python-can's send (same hop limit, same errors, same send timeout)."""

    def __init__(self, family: socket.AddressFamily, hop_limit: int, destination: tuple[str, int]) -> None:
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            hops = struct.pack("@I", hop_limit)
            if family == socket.AF_INET:
                sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, hops)
                sock.bind(("", 0))
            else:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, hops)
                sock.bind(("::", 0))
        except OSError:
            sock.close()
            raise
        self.sock = sock
        self.destination = destination
        #: UDP source port of every datagram this bus sends
        self.port: int = sock.getsockname()[1]
        #: the send timeout in force (s; None: blocking), as python-can keeps it
        self.last_timeout: float | None = None

    def send(self, data: bytes, timeout: float | None = None) -> None:
        """python-can's ``GeneralPurposeUdpMulticastBus.send`` on this socket."""
        if timeout != self.last_timeout:
            self.last_timeout = timeout
            self.sock.settimeout(timeout)
        try:
            sent = self.sock.sendto(data, self.destination)
            if sent < len(data):
                raise TimeoutError()
        except TimeoutError:
            raise can.CanTimeoutError() from None
        except OSError as error:
            raise can.CanOperationError("failed to send via socket") from error

    def close(self) -> None:
        self.sock.close()


class GuardedUdpMulticastBus(UdpMulticastBus):
    """python-can's ``UdpMulticastBus`` whose ``recv`` skips and counts (:attr:`rejects`) a
    datagram that is not a frame instead of raising ``CanOperationError``; socket errors still
    raise. Frames are unpacked by a :class:`DatagramParser` (the same result as python-can's).
    Frames are sent from a socket of its own (:attr:`tx`, :class:`UdpTransmitter`), so that its
    own datagrams can be told from other senders' by their source port."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.rejects = DatagramRejects()
        self._parser = DatagramParser()
        mc = self._multicast
        try:
            self.tx = UdpTransmitter(mc._socket.family, mc.hop_limit, mc._send_destination)
        except OSError as exc:
            mc.shutdown()
            raise can.CanInitializationError("could not create the sending socket") from exc

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """python-can's ``send``, from :attr:`tx`."""
        if self.protocol is not can.CanProtocol.CAN_FD and msg.is_fd:
            raise can.CanOperationError("cannot send FD message over bus with CAN FD disabled")
        self.tx.send(pack_message(msg), timeout)

    def shutdown(self) -> None:
        super().shutdown()
        self.tx.close()

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


_Shape = tuple[int, bool, bool, bool, object, int, int, bool, bool, bool]


class UdpWriter:
    """Sends python-can ``udp_multicast`` frames as spliced templates (see the module doc)."""

    def __init__(self, bus: GuardedUdpMulticastBus) -> None:
        self._bus = bus
        self._tx = bus.tx
        self._sock: socket.socket = bus.tx.sock
        self._dest = bus.tx.destination
        self._fd = bus.protocol is can.CanProtocol.CAN_FD
        #: shape → (head, middle, tail), or None: that shape goes through ``bus.send``
        self._templates: dict[_Shape, tuple[bytes, bytes, bytes] | None] = {}

    def prepare(self, shapes: Iterable[can.Message]) -> None:
        """Build the templates of ``shapes`` now rather than on their first send."""
        for msg in shapes:
            self._templates.setdefault(self._shape(msg), template(msg))

    @staticmethod
    def _shape(msg: can.Message) -> _Shape:
        return (
            msg.arbitration_id,
            msg.is_extended_id,
            msg.is_remote_frame,
            msg.is_error_frame,
            msg.channel,
            msg.dlc,
            len(msg.data),
            msg.is_fd,
            msg.bitrate_switch,
            msg.error_state_indicator,
        )

    def write(self, msg: can.Message) -> None:
        """Send ``msg`` as ``bus.send(msg)`` would (same datagram, same errors)."""
        if self._tx.last_timeout is not None or type(msg.timestamp) is not float:
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
        datagram = b"".join((head, F64.pack(msg.timestamp), middle, data, tail))
        try:
            sent = self._sock.sendto(datagram, self._dest)
        except TimeoutError:
            raise can.CanTimeoutError() from None
        except OSError as error:
            raise can.CanOperationError("failed to send via socket") from error
        if sent < len(datagram):
            raise can.CanTimeoutError()


def own_source_program(port: int) -> list[tuple[int, int, int, int]]:
    """The BPF program (code, jt, jf, k) of a UDP socket dropping the datagrams whose source port
    is ``port`` (a UDP socket filter sees the UDP header first: the source port is its first
    half-word) and accepting every other."""
    return [
        (_LD_H, 0, 0, 0),
        (_JEQ, 0, 1, port),  # true → next instruction (drop), false → skip it (accept)
        (_RET, 0, 0, _DROP),
        (_RET, 0, 0, _ACCEPT),
    ]


def attach_own_source_filter(bus: can.BusABC) -> bool:
    """Drop the datagrams ``bus`` itself sent (source port :attr:`UdpTransmitter.port`) in the
    kernel before they reach its receiving socket (SO_ATTACH_FILTER); True when attached."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None or not isinstance(bus, GuardedUdpMulticastBus):
        return False
    prog = own_source_program(bus.tx.port)
    buf = ctypes.create_string_buffer(b"".join(struct.pack("HBBI", *ins) for ins in prog))
    try:  # struct sock_fprog {unsigned short len; struct sock_filter *filter;}; copied by the kernel
        sock.setsockopt(
            socket.SOL_SOCKET, SO_ATTACH_FILTER, struct.pack("HL", len(prog), ctypes.addressof(buf))
        )
    except OSError:
        return False
    return True
