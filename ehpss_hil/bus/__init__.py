"""python-can bus factory from :class:`~ehpss_hil.config.BusConfig` (docs/design.md §8).

Interfaces:

- ``socketcan`` (``vcan0``/``can0``, production): ``can_filters`` are installed in the kernel.
  Raise the interface's ``txqueuelen`` (``ip link set can0 txqueuelen 1000``) against ENOBUFS.
- ``udp_multicast`` (the embedded default, no kernel module): the hop limit/TTL is always 0 so a
  frame never leaves this host, and the receive buffer is raised to
  ``cfg.receive_buffer_bytes`` (bursts of > 100 frames overflow the default buffer). The socket
  loops multicast back, so **a process receives its own frames** unless
  :func:`suppress_own_echoes` filters them out by their source port. A datagram on the group
  that is no frame (anyone on the host may send one) is counted and skipped, never raised
  (:func:`datagram_rejects`).
- ``virtual``: in-process tests and the lockstep simulator.

Own frames (:func:`suppress_own_echoes`): a CAN controller does not receive the frames it sent
itself, so one on its own TX IDs is another node's. Here: socketcan delivers a socket's own
frames back only with ``CAN_RAW_RECV_OWN_MSGS`` (python-can ``receive_own_messages``, off here),
python-can's ``virtual`` only with ``receive_own_messages`` (off here); udp_multicast loops every
datagram back to its sender, and a kernel filter on the source port drops those.

Filters on ``udp_multicast``/``virtual`` are applied by python-can in user space, and
``BusABC.recv(timeout=0)`` returns ``None`` as soon as one frame is filtered out even if more are
queued — that would end a non-blocking drain early. So filters are passed only where the kernel
applies them (socketcan); on the other interfaces the loops filter by ID themselves.

For loops that drain the bus every cycle: :func:`frame_reader` (one non-blocking read; on
``udp_multicast`` without python-can's ``select()`` per frame), :func:`frame_writer` (on
``udp_multicast`` without a dict and ``msgpack.packb`` per frame) and :func:`suppress_own_echoes`
(on ``udp_multicast`` a kernel filter for the process's own datagrams), all in
:mod:`ehpss_hil.bus.udp`.

:mod:`ehpss_hil.bus.udp` reads private attributes of python-can's ``udp_multicast`` (pinned
below python-can 5; ``tests/test_bus_udp.py`` pins the wire format), so it is imported only when a
``udp_multicast`` bus is opened or handed in: a process on socketcan or virtual never loads it.
"""

from __future__ import annotations

import logging
import socket
import sys
from collections.abc import Callable, Iterable
from functools import partial
from types import ModuleType
from typing import Any

import can

from ..config import BusConfig
from ..errors import BusUnavailableError
from .rejects import DatagramRejects

log = logging.getLogger(__name__)

_UDP_MODULE = f"{__name__}.udp"

#: Linux SO_RCVBUFFORCE (root may exceed net.core.rmem_max)
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)


def _udp() -> ModuleType:
    """:mod:`ehpss_hil.bus.udp`, imported now (the first udp_multicast bus)."""
    from . import udp

    return udp


def _is_udp_multicast(bus: can.BusABC) -> bool:
    """True for python-can's ``UdpMulticastBus`` or a subclass, told without importing it."""
    return any(
        c.__name__ == "UdpMulticastBus" and c.__module__.startswith("can.interfaces.udp_multicast")
        for c in type(bus).__mro__
    )


def _is_guarded(bus: can.BusABC) -> bool:
    """True for a :class:`~ehpss_hil.bus.udp.GuardedUdpMulticastBus` (only :func:`open_bus`
    makes one, after importing :mod:`ehpss_hil.bus.udp`)."""
    udp = sys.modules.get(_UDP_MODULE)
    return udp is not None and isinstance(bus, udp.GuardedUdpMulticastBus)


def af_can_available() -> bool:
    """True when this kernel supports ``socket(AF_CAN, SOCK_RAW, CAN_RAW)``."""
    family = getattr(socket, "AF_CAN", None)
    if family is None:
        return False
    try:
        socket.socket(family, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        return False
    return True


def open_bus(cfg: BusConfig, can_filters: list[dict[str, Any]] | None = None) -> can.BusABC:
    """Open the bus ``cfg`` describes.

    ``can_filters`` (python-can form, ``[{"can_id": .., "can_mask": ..}]``) are applied in the
    kernel on socketcan and ignored elsewhere (see the module docstring).
    Raises :class:`BusUnavailableError` when the interface or channel cannot be opened.
    """
    if cfg.interface == "socketcan":
        return _open_socketcan(cfg, can_filters)
    if cfg.interface == "udp_multicast":
        return _open_udp_multicast(cfg)
    if cfg.interface == "virtual":
        return can.Bus(interface="virtual", channel=cfg.channel, receive_own_messages=False)
    raise BusUnavailableError(f"unsupported bus interface {cfg.interface!r}")


#: interfaces :func:`open_listener_bus` opens through :func:`open_bus` (the project's own set-up)
PROJECT_INTERFACES = ("udp_multicast", "socketcan", "virtual")


def open_listener_bus(interface: str, channel: str, port: int | None = None) -> can.BusABC:
    """Open a bus to listen on (logger, monitor): the project's factory for its own interfaces,
    python-can's ``can.Bus`` for any other. ``port``: the udp_multicast port (None: default).

    Raises :class:`BusUnavailableError` when it cannot be opened.
    """
    if interface in PROJECT_INTERFACES:
        kw: dict[str, Any] = {"port": port} if port is not None else {}
        return open_bus(BusConfig(interface=interface, channel=channel, **kw))  # type: ignore[arg-type]
    try:
        return can.Bus(interface=interface, channel=channel)
    except (OSError, can.CanError, ImportError, ValueError) as exc:
        raise BusUnavailableError(f"{interface}:{channel}: cannot open ({exc})") from exc


def _open_socketcan(cfg: BusConfig, can_filters: list[dict[str, Any]] | None) -> can.BusABC:
    if not af_can_available():
        raise BusUnavailableError(
            f"socketcan:{cfg.channel}: this kernel has no SocketCAN (socket(AF_CAN) failed); "
            "use interface udp_multicast (the embedded default) or load the can/vcan modules"
        )
    try:
        return can.Bus(
            interface="socketcan",
            channel=cfg.channel,
            can_filters=can_filters,
            receive_own_messages=False,
            fd=False,
        )
    except (OSError, can.CanError) as exc:
        raise BusUnavailableError(
            f"socketcan:{cfg.channel}: cannot open the interface ({exc}); does it exist and is it "
            f"up? (e.g. 'ip link add dev {cfg.channel} type vcan; ip link set {cfg.channel} up')"
        ) from exc


def _open_udp_multicast(cfg: BusConfig) -> can.BusABC:
    if cfg.hop_limit != 0:  # BusConfig validates this too; never send beyond this host
        raise BusUnavailableError("udp_multicast requires hop_limit 0 (frames stay on this host)")
    try:
        bus = _udp().GuardedUdpMulticastBus(channel=cfg.channel, port=cfg.port, hop_limit=0, fd=False)
    except (OSError, can.CanError) as exc:
        raise BusUnavailableError(
            f"udp_multicast:{cfg.channel}:{cfg.port}: cannot open ({exc}); a multicast route is "
            "needed (inside a private namespace: 'ip link set lo up; "
            "ip route add 224.0.0.0/4 dev lo')"
        ) from exc
    set_receive_buffer(bus, cfg.receive_buffer_bytes)
    return bus


def datagram_rejects(bus: can.BusABC) -> DatagramRejects | None:
    """The counter of datagrams skipped as no frame (udp_multicast from :func:`open_bus`), or
    None on a bus that cannot receive such datagrams."""
    return bus.rejects if _is_guarded(bus) else None  # type: ignore[attr-defined, no-any-return]


def set_receive_buffer(bus: can.BusABC, size_bytes: int) -> int:
    """Raise the UDP socket's receive buffer to ``size_bytes``; returns the size granted (bytes).

    Tries SO_RCVBUFFORCE (root) first, then SO_RCVBUF (capped by net.core.rmem_max); warns when
    the kernel grants less than asked. Returns 0 when the bus has no such socket.
    """
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return 0
    for opt in (_SO_RCVBUFFORCE, socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, size_bytes)
            break
        except OSError:
            continue
    granted = int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    if granted < size_bytes:  # Linux reports twice the requested value when it is granted
        log.warning(
            "udp_multicast: receive buffer %d bytes < requested %d (raise net.core.rmem_max or run as root)",
            granted,
            size_bytes,
        )
    return granted


#: python-can interfaces that stamp a received frame with the kernel's receive time
#: (``SO_TIMESTAMPNS``, CLOCK_REALTIME: the clock of ``time.time()``); ``virtual`` stamps the
#: sender's ``time.time()`` at send instead
_RECEIVE_STAMPED = ("UdpMulticastBus", "SocketcanBus")


def stamps_receive_time(bus: can.BusABC) -> bool:
    """True when ``msg.timestamp`` of a received frame is its receive time on the host's wall
    clock (udp_multicast, socketcan), so that its age can be told at any later moment."""
    return type(bus).__name__ in _RECEIVE_STAMPED


def frame_reader(bus: can.BusABC, shapes: Iterable[can.Message] = ()) -> Callable[[], can.Message | None]:
    """One pending frame or None, never waiting: ``bus.recv(0.0)``, or on ``udp_multicast`` the
    same read without its ``select()`` system call (:class:`~ehpss_hil.bus.udp.UdpReader`),
    with the templates of ``shapes`` (frames like those to come) built now, not on arrival."""
    if _is_udp_multicast(bus) and _udp().UdpReader.supports(bus):
        reader = _udp().UdpReader(bus)
        reader.prepare(shapes)
        return reader.read
    return partial(bus.recv, 0.0)


def frame_writer(bus: can.BusABC, shapes: Iterable[can.Message] = ()) -> Callable[[can.Message], None]:
    """Send one frame: ``bus.send``, or on ``udp_multicast`` the same datagram built from a
    per-frame-shape template (:class:`~ehpss_hil.bus.udp.UdpWriter`; the templates of
    ``shapes`` built now, not on the first send)."""
    if _is_guarded(bus):
        writer = _udp().UdpWriter(bus)
        writer.prepare(shapes)
        return writer.write
    return bus.send


def suppress_own_echoes(bus: can.BusABC) -> bool:
    """Keep ``bus`` from handing this process back the frames it sent itself, where it would
    (a kernel socket filter on the source port on ``udp_multicast``); True when none ever comes
    back, so that a frame received on one of the process's own TX IDs is another node's. False:
    own frames may come back (python-can's plain ``UdpMulticastBus``, a bus opened with
    ``receive_own_messages``, an unknown interface) and the caller must tell them apart."""
    if _is_udp_multicast(bus):
        ok: bool = _udp().attach_own_source_filter(bus)
        if not ok:
            log.warning("udp_multicast: own frames are told apart in user space (kernel filter not attached)")
        return ok
    kind = type(bus).__name__
    if kind == "SocketcanBus":
        from can.interfaces.socketcan.constants import CAN_RAW_RECV_OWN_MSGS, SOL_CAN_RAW

        try:
            return (
                bus.socket.getsockopt(  # type: ignore[attr-defined, no-any-return]
                    SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS
                )
                == 0
            )
        except OSError:
            return False
    if kind == "VirtualBus":
        return getattr(bus, "receive_own_messages", True) is False
    return False
