"""FAULT_INJECT frames (bench only): kind + value → a checked fault override for the emulation.

Kinds follow the DBC VAL_ table; values outside the scenario format's ranges are rejected.
"""

from __future__ import annotations

import math
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


def parse_inject(values: dict[str, Any]) -> dict[str, float | bool] | None:
    """``{key: value}`` for :meth:`PlantEmulation.inject`, ``{}`` for *clear*, None if invalid."""
    kind = int(values.get("FaultKind", -1))
    if kind == CLEAR:
        return {}
    spec = KINDS.get(kind)
    value = float(values.get("Value", math.nan))
    if spec is None or not math.isfinite(value):
        return None
    key, lo, hi, lo_open = spec
    if value > hi or value < lo or (lo_open and value == lo):
        return None
    if key == "stuck":
        return {key: value >= 0.5}
    return {key: value}
