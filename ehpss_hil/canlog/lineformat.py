"""The ``candump -L`` line (can-utils ``lib.c``): ``(%010u.%06u) IFACE ID#DATA`` with a 3-digit
(standard) or 8-digit (extended) upper-case hex ID, upper-case hex data, ``ID#R[dlc]`` for remote
frames and ``ID##<flags>DATA`` for CAN FD; the error-frame ID flags; the longest line a frame makes.
Written by :mod:`~ehpss_hil.canlog.writer`, parsed by :mod:`~ehpss_hil.canlog.reader`.
"""

from __future__ import annotations

CAN_ERR_FLAG = 0x20000000
CAN_ERR_BUSERROR = 0x00000080
#: the longest line a frame can make (CAN FD, 64 bytes, 8-digit ID, 16-character interface name)
MAX_LINE_BYTES = 20 + 16 + 1 + 8 + 3 + 128 + 1

#: a queued frame: timestamp (s), ID, extended, remote, error, FD, BRS, ESI, DLC, data
FrameItem = tuple[float, int, bool, bool, bool, bool, bool, bool, int, bytes]


def format_line(item: FrameItem, iface: str) -> str:
    """One ``candump -L`` line (with ``\\n``) for a queued frame tuple (:data:`FrameItem`)."""
    ts, can_id, ext, rtr, err, fd, brs, esi, dlc, data = item
    usec = max(0, round(ts * 1e6))
    sec, usec = divmod(usec, 1_000_000)
    if err:
        ident = f"{CAN_ERR_FLAG | CAN_ERR_BUSERROR | (can_id & 0x1FFFFFFF):08X}"
    elif ext:
        ident = f"{can_id:08X}"
    else:
        ident = f"{can_id:03X}"
    if rtr:
        body = "R" + (f"{dlc:X}" if 0 < dlc <= 8 else "")
    elif fd:
        body = f"#{(1 if brs else 0) | (2 if esi else 0):X}{data.hex().upper()}"
    else:
        body = data.hex().upper()
    return f"({sec:010d}.{usec:06d}) {iface} {ident}#{body}\n"
