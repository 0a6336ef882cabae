"""The piston travel a profile's position field must hold.

A position reading outside the field's range is OUT_OF_RANGE (the receiver drops it; the
emulator cannot send it), so a DBC whose position range is narrower than where the controller
sends the piston stops the loop in the middle of a run. ``check-config``, the controller and
``sim --protocol`` refuse it first: the field must hold the largest |x_d| the controller is
given (its reference, and SETPOINT's ``max_abs_m`` when SETPOINT is enabled) with
:data:`POSITION_RANGE_MARGIN` to spare (overshoot, a reading past the reference).
"""

from __future__ import annotations

from ..codec import FrameCodec
from ..config import ControllerConfig
from ..errors import ConfigError
from ..scenario import Reference

#: the position field holds this many times the largest commanded |x_d|
POSITION_RANGE_MARGIN = 1.2


def reference_extent_m(ref: Reference) -> float:
    """The largest |x_d| of ``ref`` (m): its amplitude (every kind is bounded by it) or, for a
    file, the table's largest |x|."""
    if ref.kind == "file":
        table = ref.loaded().table
        assert table is not None
        return float(abs(table.x_m).max())
    return ref.amplitude_m


def commanded_travel_m(cfg: ControllerConfig) -> tuple[float, str]:
    """(largest |x_d| the controller of ``cfg`` is given (m), the config key it comes from)."""
    ref = reference_extent_m(cfg.reference)
    if cfg.setpoint.enabled and cfg.setpoint.max_abs_m > ref:
        return cfg.setpoint.max_abs_m, "setpoint.max_abs_m"
    return ref, "reference"


def _field(cfg_protocol: str, cfg: ControllerConfig | None) -> tuple[str, str]:
    """(config key, signal name) of the position field of a profile."""
    if cfg_protocol == "dbc-map" and cfg is not None and cfg.dbc_map is not None:
        return "dbc_map.signals.position", cfg.dbc_map.signals.position
    if cfg_protocol == "cia408":
        return "cia408.position_source", "the position object"
    return "dbc", "SENSOR_POS.Position"


def check_position_range(
    codec: FrameCodec, travel_m: float, why: str, src: str, cfg: ControllerConfig | None = None
) -> None:
    """``codec``'s position field holds ±:data:`POSITION_RANGE_MARGIN` × ``travel_m`` (m), or a
    ConfigError naming the field's key (``why``: where the travel comes from)."""
    lo, hi = codec.signal_bounds("SENSOR_POS").get("Position", (None, None))
    need = POSITION_RANGE_MARGIN * travel_m
    if (lo is None or lo <= -need) and (hi is None or hi >= need):
        return
    key, name = _field(cfg.protocol if cfg is not None else "native", cfg)
    raise ConfigError(
        src,
        key,
        f"{name} holds [{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}] m; "
        f"the piston is sent to ±{travel_m:g} m ({why}), so the field must hold ±{need:g} m "
        f"(×{POSITION_RANGE_MARGIN:g})",
    )


def check_controller_travel(codec: FrameCodec, cfg: ControllerConfig, src: str) -> None:
    """:func:`check_position_range` for the travel of controller config ``cfg``."""
    travel, why = commanded_travel_m(cfg)
    check_position_range(codec, travel, why, src, cfg)
