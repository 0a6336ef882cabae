"""FAULT_INJECT frames (bench only): kind + value → a checked fault override for the emulation,
and the status the emulator answers with (FAULT_INJECT_ACK), so the sender learns whether it
was applied and, if not, why.

Kinds follow the DBC VAL_ table; values outside the scenario format's ranges are refused.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import Any

#: FaultKind → (key, lowest, highest, low end open)
KINDS: dict[int, tuple[str, float, float, bool]] = {
    0: ("k_loe", 0.0, 1.5, True),
    1: ("k_q", 0.0, 1.5, True),
    2: ("k_dft", 0.0, 2.5, False),
    3: ("position_bias_m", -0.1, 0.1, False),
    4: ("stuck", 0.0, 1.0, False),
    5: ("frame_loss", 0.0, 1.0, False),
    6: ("current_limit_a", 0.0, 1.0, True),
}
CLEAR = 7


class InjectStatus(IntEnum):
    """FAULT_INJECT_ACK ``Status`` (the DBC's value table names them alike)."""

    APPLIED = 0
    OUT_OF_RANGE = 1
    INJECTION_OFF = 2
    INVALID_FRAME = 3
    UNKNOWN_KIND = 4


def check_inject(values: dict[str, Any]) -> tuple[InjectStatus, dict[str, float | bool] | None]:
    """``(APPLIED, {key: value})`` for :meth:`PlantEmulation.inject` (``{}``: *clear*), else
    ``(why, None)``: an unknown kind, or a value outside the kind's range or not finite."""
    kind = int(values.get("FaultKind", -1))
    if kind == CLEAR:
        return InjectStatus.APPLIED, {}
    spec = KINDS.get(kind)
    if spec is None:
        return InjectStatus.UNKNOWN_KIND, None
    value = float(values.get("Value", math.nan))
    key, lo, hi, lo_open = spec
    if not math.isfinite(value) or value > hi or value < lo or (lo_open and value == lo):
        return InjectStatus.OUT_OF_RANGE, None
    if key == "stuck":
        return InjectStatus.APPLIED, {key: value >= 0.5}
    return InjectStatus.APPLIED, {key: value}


def ack_values(status: InjectStatus, values: dict[str, Any] | None) -> dict[str, float]:
    """The FAULT_INJECT_ACK signals answering a FAULT_INJECT with ``values`` (None: the frame
    did not decode): its kind and value echoed (15 and 0 when unknown or not finite)."""
    v = values or {}
    kind = int(v.get("FaultKind", 15))
    value = float(v.get("Value", 0.0))
    return {
        "FaultKind": kind if 0 <= kind <= 15 else 15,
        "Status": int(status),
        "Value": value if math.isfinite(value) else 0.0,
    }
