"""The CANopen master's start-up of a CiA 408 valve and a CiA 406 encoder (issue #18 item 3, its
first steps): each node's identity checked by SDO, the heartbeat producer time set, NMT start,
the OPERATIONAL state confirmed in the heartbeat; and the NMT stop at the end.

It runs before the control loop, through ``canopen``'s master (``Network`` with its notifier
thread, ``RemoteNode``: SDO client, NMT): blocking calls with time limits are what start-up
needs, and the loop's cycle never goes through them. Failures are :class:`NodeError` (exit 3),
one line naming the node.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from canopen.nmt import NmtError
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from ...errors import NodeError
from .objects import DEVICE_TYPE, IDENTITY, PRODUCER_HEARTBEAT, PROFILE_ENCODER, PROFILE_VALVE

#: heartbeat producer time the master sets on each node at start-up (ms)
STARTUP_HEARTBEAT_MS = 100
#: how long the master waits for an SDO answer and for the OPERATIONAL heartbeat (s)
SDO_TIMEOUT_S = 1.0
STATE_TIMEOUT_S = 2.0


@dataclass(frozen=True)
class NodeIdentity:
    """What a node says it is: 0x1000 and 0x1018.1…4."""

    node_id: int
    device_type: int
    vendor_id: int
    product_code: int
    revision: int
    serial: int

    @property
    def profile(self) -> int:
        """The device profile number (the device type's low word: 408, 406, …)."""
        return self.device_type & 0xFFFF

    def text(self) -> str:
        """One line for the log: ``node 32: CiA 408 (device type 0x00000198), vendor 0x…``."""
        return (
            f"node {self.node_id}: CiA {self.profile} (device type 0x{self.device_type:08X}), vendor "
            f"0x{self.vendor_id:08X}, product 0x{self.product_code:08X}, revision 0x{self.revision:08X}, "
            f"serial 0x{self.serial:08X}"
        )


def _read(node: Any, index: int, sub: int | None, role: str) -> int:
    try:
        obj = node.sdo[index] if sub is None else node.sdo[index][sub]
        return int(obj.raw)
    except (SdoAbortedError, SdoCommunicationError) as exc:
        where = f"0x{index:04X}" + (f".{sub}" if sub is not None else "")
        raise NodeError(f"{role} node {node.id}: SDO read of {where} failed: {exc}") from exc


def read_identity(node: Any, role: str) -> NodeIdentity:
    """The identity of ``node`` (a ``canopen.RemoteNode``) by SDO."""
    node.sdo.RESPONSE_TIMEOUT = SDO_TIMEOUT_S
    return NodeIdentity(
        node.id,
        _read(node, DEVICE_TYPE, None, role),
        *(_read(node, IDENTITY, sub, role) for sub in (1, 2, 3, 4)),
    )


def check_identity(node: Any, profile: int, role: str) -> NodeIdentity:
    """The identity of ``node``; a device of another profile than ``profile`` is a NodeError."""
    ident = read_identity(node, role)
    if ident.profile != profile:
        raise NodeError(
            f"{role} node {node.id}: device type 0x{ident.device_type:08X} is CiA {ident.profile}, "
            f"expected CiA {profile}"
        )
    return ident


def await_state(node: Any, state: str, role: str) -> None:
    """Heartbeats until one shows ``state`` (one sent before the command may come first)."""
    end = time.monotonic() + STATE_TIMEOUT_S
    seen = None
    while time.monotonic() < end:
        try:
            seen = node.nmt.wait_for_heartbeat(max(end - time.monotonic(), 0.0))
        except NmtError:
            break
        if seen == state:
            return
    raise NodeError(
        f"{role} node {node.id}: no heartbeat showing {state} within {STATE_TIMEOUT_S:g} s "
        f"(last seen: {seen or 'none'})"
    )


def start_node(node: Any, profile: int, role: str) -> NodeIdentity:
    """Identity check, heartbeat producer time, NMT start confirmed by the heartbeat."""
    ident = check_identity(node, profile, role)
    try:
        node.sdo[PRODUCER_HEARTBEAT].raw = STARTUP_HEARTBEAT_MS
    except (SdoAbortedError, SdoCommunicationError) as exc:
        raise NodeError(f"{role} node {node.id}: cannot set the heartbeat time (0x1017): {exc}") from exc
    go_operational(node, role)
    return ident


def go_operational(node: Any, role: str) -> None:
    """NMT start, confirmed by a heartbeat showing OPERATIONAL."""
    node.nmt.state = "OPERATIONAL"
    await_state(node, "OPERATIONAL", role)


def start_nodes(valve: Any, encoder: Any) -> tuple[NodeIdentity, NodeIdentity]:
    """Start-up of the valve (CiA 408) and the encoder (CiA 406), in that order."""
    return start_node(valve, PROFILE_VALVE, "valve"), start_node(encoder, PROFILE_ENCODER, "encoder")


def stop_nodes(*nodes: Any) -> None:
    """NMT stop of each node (no answer is awaited: a stopped node still sends its heartbeat)."""
    for node in nodes:
        node.nmt.state = "STOPPED"
