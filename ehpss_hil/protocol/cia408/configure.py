"""The master's start-up configuration of its nodes by SDO (PRE-OPERATIONAL, before NMT start):
PDO mappings and transmission types, heartbeat producer and consumer times, the valve's device
mode, and the encoder's measuring step read back for the position scaling.

What it writes (node n; the PDO layouts of :mod:`.cyclic`):

* both nodes: 0x1017 producer heartbeat time = ``heartbeat_time_ms``;
* the valve: 0x1016.1 consumer heartbeat = ``master_node << 16 | master_heartbeat_timeout_ms``;
  0x6042 device mode 1 (set-point via the bus), 0x6043 device control mode 1 (spool position,
  open loop); RPDO 1: 0x1600 = [0x6040 (16 bit), 0x6300.1 (16 bit)], 0x1400.2 = 1 (synchronous:
  the set-point applies at the SYNC the master sends after it), 0x1400.5 event timer =
  ``setpoint_timeout_ms``; TPDO 1: 0x1A00 = [0x6041, 0x6301.1], 0x1800.2 = 1 (every SYNC);
  the set-point path the controller relies on, where the valve's EDS has it (a valve may come
  with limits or a ramp set, which would shape our commands): limits 0x6320.1 = +100 %, 0x6321.1
  = −100 %, ramp type 0x6330 = 0 (none), hold set-point 0x6314.1 = 0;
* with ``position_source: valve``, the valve's TPDO 2: 0x1A01 = [``valve_position_object``
  (32 bit)], 0x1801.2 = 1, COB-ID 0x280+n (and no encoder);
* the encoder: TPDO 1: 0x1A00 = [0x6004 (32 bit)], 0x1800.2 = 1; 0x6005.1 read.

A PDO is remapped as CiA 301 asks: its COB-ID marked invalid (bit 31), the mapping count 0, the
entries, the count, then the valid COB-ID. Every failure is a :class:`NodeError` naming the node
and the object.
"""

from __future__ import annotations

from typing import Any

from canopen.sdo import SdoAbortedError, SdoCommunicationError

from ...config import Cia408Config
from ...errors import NodeError
from . import cobid
from .objects import (
    CONSUMER_HEARTBEAT,
    CONTROL_MODE_SPOOL_OPEN_LOOP,
    CONTROL_WORD,
    DEVICE_CONTROL_MODE,
    DEVICE_MODE,
    DEVICE_MODE_SETPOINT_VIA_BUS,
    MEASURING_STEP,
    PDO_COB_ID,
    PDO_EVENT_TIMER,
    PDO_INVALID,
    PDO_TRANSMISSION,
    POSITION_VALUE,
    PRODUCER_HEARTBEAT,
    RAMP_NONE,
    RPDO_COMM,
    RPDO_MAP,
    SCALE_100_PERCENT,
    STATUS_WORD,
    TPDO_COMM,
    TPDO_MAP,
    VPOC_ACTUAL,
    VPOC_HOLD_SETPOINT,
    VPOC_LOWER_LIMIT,
    VPOC_RAMP_TYPE,
    VPOC_SETPOINT,
    VPOC_SUB,
    VPOC_UPPER_LIMIT,
)

#: transmission type of every PDO the master configures: synchronous, every SYNC
SYNC_EVERY = 1
#: the mapping entries of the PDOs: (index, sub-index, bits)
VALVE_RPDO_MAP = ((CONTROL_WORD, 0, 16), (VPOC_SETPOINT, VPOC_SUB, 16))
VALVE_TPDO_MAP = ((STATUS_WORD, 0, 16), (VPOC_ACTUAL, VPOC_SUB, 16))
ENCODER_TPDO_MAP = ((POSITION_VALUE, 0, 32),)
#: the valve's set-point path as the controller relies on it: (index, sub-index or None, value)
VALVE_SETPOINT_PATH = (
    (VPOC_UPPER_LIMIT, VPOC_SUB, SCALE_100_PERCENT),
    (VPOC_LOWER_LIMIT, VPOC_SUB, -SCALE_100_PERCENT),
    (VPOC_RAMP_TYPE, None, RAMP_NONE),
    (VPOC_HOLD_SETPOINT, VPOC_SUB, 0),
)


def write(node: Any, index: int, sub: int | None, value: int, role: str) -> None:
    """One SDO download (``sub`` None: a variable at the index itself)."""
    try:
        var = node.sdo[index] if sub is None else node.sdo[index][sub]
        var.raw = value
    except (SdoAbortedError, SdoCommunicationError, KeyError) as exc:
        where = f"0x{index:04X}" + (f".{sub}" if sub is not None else "")
        raise NodeError(f"{role} node {node.id}: SDO write of {where} = {value} failed: {exc}") from exc


def read(node: Any, index: int, sub: int | None, role: str) -> int:
    """One SDO upload."""
    try:
        var = node.sdo[index] if sub is None else node.sdo[index][sub]
        return int(var.raw)
    except (SdoAbortedError, SdoCommunicationError, KeyError) as exc:
        where = f"0x{index:04X}" + (f".{sub}" if sub is not None else "")
        raise NodeError(f"{role} node {node.id}: SDO read of {where} failed: {exc}") from exc


def map_pdo(
    node: Any,
    comm: int,
    mapping: int,
    can_id: int,
    entries: tuple[tuple[int, int, int], ...],
    role: str,
    event_timer_ms: int | None = None,
) -> None:
    """Remap one PDO (communication object ``comm``, mapping object ``mapping``) to ``entries``
    on COB-ID ``can_id``, synchronous on every SYNC."""
    write(node, comm, PDO_COB_ID, can_id | PDO_INVALID, role)
    write(node, mapping, 0, 0, role)
    for sub, (index, s, bits) in enumerate(entries, start=1):
        write(node, mapping, sub, index << 16 | s << 8 | bits, role)
    write(node, mapping, 0, len(entries), role)
    write(node, comm, PDO_TRANSMISSION, SYNC_EVERY, role)
    if event_timer_ms is not None:
        write(node, comm, PDO_EVENT_TIMER, event_timer_ms, role)
    write(node, comm, PDO_COB_ID, can_id, role)


def configure_valve(node: Any, c: Cia408Config) -> None:
    """The valve's heartbeats, device mode and PDOs (module docstring)."""
    role = "valve"
    write(node, PRODUCER_HEARTBEAT, None, c.heartbeat_time_ms, role)
    write(node, CONSUMER_HEARTBEAT, 1, c.master_node << 16 | c.master_heartbeat_timeout_ms, role)
    write(node, DEVICE_MODE, None, DEVICE_MODE_SETPOINT_VIA_BUS, role)
    write(node, DEVICE_CONTROL_MODE, None, CONTROL_MODE_SPOOL_OPEN_LOOP, role)
    for index, sub, value in VALVE_SETPOINT_PATH:
        if index in node.object_dictionary:
            write(node, index, sub, value, role)
    n = node.id
    map_pdo(node, RPDO_COMM, RPDO_MAP, cobid.RPDO1 + n, VALVE_RPDO_MAP, role, c.setpoint_timeout_ms)
    map_pdo(node, TPDO_COMM, TPDO_MAP, cobid.TPDO1 + n, VALVE_TPDO_MAP, role)
    if c.position_source == "valve":
        entry = ((c.valve_position_object, c.valve_position_sub, 32),)
        map_pdo(node, TPDO_COMM + 1, TPDO_MAP + 1, cobid.TPDO2 + n, entry, role)


def configure_encoder(node: Any, c: Cia408Config) -> int:
    """The encoder's heartbeat and TPDO; returns its measuring step 0x6005.1 (nm)."""
    role = "encoder"
    write(node, PRODUCER_HEARTBEAT, None, c.heartbeat_time_ms, role)
    map_pdo(node, TPDO_COMM, TPDO_MAP, cobid.TPDO1 + node.id, ENCODER_TPDO_MAP, role)
    step_nm = read(node, MEASURING_STEP, 1, role)
    if step_nm <= 0:
        raise NodeError(f"encoder node {node.id}: measuring step 0x6005.1 is {step_nm} nm")
    return step_nm
