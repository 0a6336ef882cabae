"""The CiA 301 predefined connection set: COB-IDs of the standard services (11-bit IDs).

A node ``n`` (1…127) owns EMCY 0x080+n, TPDO1…4 0x180/0x280/0x380/0x480+n, RPDO1…4
0x200/0x300/0x400/0x500+n, SDO server→client 0x580+n, client→server 0x600+n and its heartbeat
(NMT error control) 0x700+n; NMT commands are 0x000 and SYNC 0x080 (node-less).
"""

from __future__ import annotations

NMT = 0x000
SYNC = 0x080
EMCY = 0x080
TPDO1, TPDO2, TPDO3, TPDO4 = 0x180, 0x280, 0x380, 0x480
RPDO1, RPDO2, RPDO3, RPDO4 = 0x200, 0x300, 0x400, 0x500
SDO_TX = 0x580  #: server → client (the node's answers)
SDO_RX = 0x600  #: client → server (requests to the node)
HEARTBEAT = 0x700
#: node ids a CANopen node may have
NODE_MIN, NODE_MAX = 1, 127

#: function code bases (COB-ID without the node id) and their names, in ID order
_FUNCTIONS = (
    (EMCY, "EMCY"),
    (TPDO1, "TPDO1"),
    (RPDO1, "RPDO1"),
    (TPDO2, "TPDO2"),
    (RPDO2, "RPDO2"),
    (TPDO3, "TPDO3"),
    (RPDO3, "RPDO3"),
    (TPDO4, "TPDO4"),
    (RPDO4, "RPDO4"),
    (SDO_TX, "SDO_TX"),
    (SDO_RX, "SDO_RX"),
    (HEARTBEAT, "HEARTBEAT"),
)


def classify(can_id: int) -> tuple[str, int]:
    """The service of a frame by its 11-bit COB-ID and the node it belongs to (0: node-less):
    ``("NMT", 0)``, ``("SYNC", 0)``, ``("TPDO1", 32)``, … ; ``("UNKNOWN", 0)`` for an ID outside
    the predefined set (TIME 0x100, 0x101…0x17F, extended IDs, …)."""
    if can_id == NMT:
        return "NMT", 0
    if can_id == SYNC:
        return "SYNC", 0
    base, node = can_id & ~0x7F, can_id & 0x7F
    if node >= NODE_MIN and can_id <= 0x7FF:
        for b, name in _FUNCTIONS:
            if base == b:
                return name, node
    return "UNKNOWN", 0
