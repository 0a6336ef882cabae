"""One colour per reason the controller leaves normal operation for, shared by the report's
figures and the live monitor's plots (the page receives this table from the server).

Keys are the DBC value-table names: CTRL_STATUS ``FailsafeReason`` (the controller in FAULT) and
CTRL_STATS ``FallbackReason`` (the do-no-harm monitor holding the loop on nominal compensation).
Colours are CSS hex strings, which matplotlib reads as they are.
"""

from __future__ import annotations

#: CTRL_STATUS FailsafeReason name → shading colour of a FAULT interval
FAILSAFE_COLORS: dict[str, str] = {
    "NONE": "#7f7f7f",
    "SENSOR_TIMEOUT": "#d62728",
    "E2E_ERRORS": "#9467bd",
    "PLAUSIBILITY": "#8c564b",
    "OPERATOR": "#17becf",
    "LOOP_OVERRUN": "#e377c2",
    "ID_COLLISION": "#bcbd22",
    "DEVICE_FAULT": "#1f77b4",
    "EMCY": "#393b79",
    "HEARTBEAT_LOST": "#637939",
    "BUS_ERROR": "#843c39",
    "PDO_ERROR": "#7b4173",
}
#: CTRL_STATS FallbackReason name → shading colour of a fallback interval ("" : no reason sent)
FALLBACK_COLORS: dict[str, str] = {
    "": "#fdae6b",
    "NONE": "#fdae6b",
    "PRODUCT_MISMATCH": "#ff7f0e",
    "ESTIMATE_AT_LIMIT": "#e6550d",
}
#: the colour of a reason missing from the tables (a DBC newer than this module)
UNKNOWN_COLOR = "#999999"
#: interval kind (report.annotate.Interval.kind) → its table
KIND_COLORS: dict[str, dict[str, str]] = {"FAULT": FAILSAFE_COLORS, "fallback": FALLBACK_COLORS}


def reason_color(kind: str, reason: str) -> str:
    """The shading colour of an interval of ``kind`` ("FAULT" or "fallback") for ``reason``."""
    return KIND_COLORS.get(kind, {}).get(reason, UNKNOWN_COLOR)
