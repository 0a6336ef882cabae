"""python-can ``udp_multicast`` at the cost a 1 kHz loop can afford.

Two things python-can's generic path does per frame that a loop draining the bus every cycle
does not need:

- ``bus.recv(0.0)`` calls ``select()`` before every ``recvmsg()``: two system calls per frame
  and one more to learn that nothing is left. :class:`UdpReader` reads the socket directly with
  ``MSG_DONTWAIT`` and otherwise does what python-can's ``UdpMulticastBus._recv_internal``
  does: the kernel receive timestamp (``SO_TIMESTAMPNS``), ``unpack_message(check=True)``, the
  same errors. (One difference: python-can's ``recv`` treats a frame with DLC 0 as "no frame" —
  ``if msg`` on a Message is its length — and drops it unlogged; here it is returned.)
- The socket loops every frame back to its sender, so a process receives all its own frames
  and drops them after decoding. :func:`attach_own_id_filter` installs a classic BPF socket
  filter that drops them in the kernel. It matches the msgpack layout python-can's
  ``pack_message`` produces (a map whose first keys are ``timestamp`` as float64 and
  ``arbitration_id``); a datagram that does not start that way is accepted, so the filter can
  only ever drop the listed IDs, and :class:`~ehpss_hil.runtime.frameio.FrameIO` still drops
  own IDs itself.
"""

from __future__ import annotations

import ctypes
import socket
import struct
from collections.abc import Iterable

import can
import msgpack
from can.interfaces.udp_multicast import UdpMulticastBus
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_TIMESPEC = struct.Struct("@ll")
_UDP_HEADER = 8  # a UDP socket filter sees the UDP header first

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

    @staticmethod
    def supports(bus: can.BusABC) -> bool:
        """True for a udp_multicast bus with kernel timestamps (Linux)."""
        mc = getattr(bus, "_multicast", None)
        return (isinstance(bus, UdpMulticastBus) and mc is not None
                and getattr(mc, "timestamp_nanosecond", False) and hasattr(mc, "_socket"))

    def read(self) -> can.Message | None:
        """One pending frame, or None when none is pending (never waits)."""
        sock = self._sock
        if sock.gettimeout() is not None:  # a send timeout made recvmsg wait: python-can's path
            return self._bus.recv(0.0)
        try:
            data, anc, _flags, _addr = sock.recvmsg(self._max, self._anc, socket.MSG_DONTWAIT)
        except BlockingIOError:
            return None
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
        try:
            msg = unpack_message(data, replace={"timestamp": seconds + nanoseconds * 1.0e-9},
                                 check=True)
        except Exception as exc:
            raise can.CanOperationError("could not unpack received message") from exc
        if not self._fd and msg.is_fd:
            return None
        return msg


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
    ts = b"\x8b" + msgpack.packb("timestamp") + b"\xcb"  # fixmap(11), key, float64 tag
    key = msgpack.packb("arbitration_id")
    at_key = len(ts) + 8
    at_id = at_key + len(key)
    ids = sorted(set(can_ids))
    blocks: list[tuple[list[tuple[int, int | str, int]], str]] = []
    for i, can_id in enumerate(ids):
        enc = msgpack.packb(can_id)
        probe = pack_message(can.Message(arbitration_id=can_id, timestamp=1.5,
                                         is_extended_id=can_id > 0x7FF))
        if not (probe.startswith(ts) and probe[at_key:at_id] == key
                and probe[at_id:at_id + len(enc)] == enc):
            return None
        blocks.append((_expect(_UDP_HEADER + at_id, enc, f"next{i}"), f"next{i}"))
    if not blocks:
        return None
    longest = max(len(msgpack.packb(i)) for i in ids)
    # a shorter datagram is accepted (a load beyond the packet would make the kernel drop it)
    code: list[tuple[int, int | str, int]] = [(_LD_LEN, 0, 0),
                                              (_JGE, "accept", _UDP_HEADER + at_id + longest)]
    code += _expect(_UDP_HEADER, ts, "accept")
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
