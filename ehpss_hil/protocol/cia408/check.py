"""Checks of a ``cia408:`` section before any bus is opened (``firmware-sim``, ``check-config``):
the set-point's resolution and the two EDS files (they load, declare the right profile, hold the
objects the emulator serves). Each failure is one :class:`ConfigError` naming its key."""

from __future__ import annotations

from typing import Any

from canopen.objectdictionary import INTEGER32

from ...config import Cia408Config
from ...errors import ConfigError
from ..logical import CURRENT_RESOLUTION_A, POSITION_RESOLUTION_M
from .eds import ENCODER_EDS, VALVE_EDS, load_od
from .objects import (
    CONTROL_WORD,
    DEVICE_TYPE,
    IDENTITY,
    MEASURING_STEP,
    POSITION_VALUE,
    PRODUCER_HEARTBEAT,
    PROFILE_ENCODER,
    PROFILE_VALVE,
    RPDO_COMM,
    RPDO_MAP,
    SCALE_100_PERCENT,
    STATUS_WORD,
    TPDO_COMM,
    TPDO_MAP,
    VPOC_ACTUAL,
    VPOC_SETPOINT,
    VPOC_SUB,
)

#: (index, sub-index) each emulated node serves; sub None: the object itself
_COMMON = ((DEVICE_TYPE, None), (IDENTITY, 1), (PRODUCER_HEARTBEAT, None), (TPDO_COMM, 2), (TPDO_MAP, 1))
VALVE_OBJECTS = (
    *_COMMON,
    (RPDO_COMM, 5),
    (RPDO_MAP, 1),
    (CONTROL_WORD, None),
    (STATUS_WORD, None),
    (VPOC_SETPOINT, VPOC_SUB),
    (VPOC_ACTUAL, VPOC_SUB),
)
ENCODER_OBJECTS = (*_COMMON, (POSITION_VALUE, None), (MEASURING_STEP, 1))


def _check_od(od: Any, profile: int, objects: tuple[tuple[int, int | None], ...], src: str, key: str) -> None:
    for index, sub in objects:
        if index not in od or (sub is not None and sub not in od[index]):
            where = f"0x{index:04X}" + (f".{sub}" if sub is not None else "")
            raise ConfigError(src, key, f"the EDS has no object {where}, which the emulated node serves")
    declared = od[DEVICE_TYPE].default or 0
    if declared & 0xFFFF != profile:
        raise ConfigError(src, key, f"device type 0x{declared:08X} is not CiA {profile} (low word {profile})")


def check_nodes(c: Cia408Config, src: str) -> tuple[Any, Any]:
    """The object dictionaries of the valve and the encoder (``canopen`` objects) after the
    checks; raises :class:`ConfigError`."""
    lsb = c.full_scale_current_a / SCALE_100_PERCENT
    if lsb > CURRENT_RESOLUTION_A * (1 + 1e-9):
        raise ConfigError(
            src,
            "cia408.full_scale_current_a",
            f"{c.full_scale_current_a:g} A over {SCALE_100_PERCENT} steps is a {lsb * 1e6:.2f} µA LSB, "
            f"coarser than the controller's {CURRENT_RESOLUTION_A * 1e6:g} µA "
            f"(at most {CURRENT_RESOLUTION_A * SCALE_100_PERCENT:g} A)",
        )
    valve = load_od(c.valve_eds or VALVE_EDS, c.valve_node, src, "cia408.valve_eds")
    _check_od(valve, PROFILE_VALVE, VALVE_OBJECTS, src, "cia408.valve_eds")
    encoder = load_od(c.encoder_eds or ENCODER_EDS, c.encoder_node, src, "cia408.encoder_eds")
    _check_od(encoder, PROFILE_ENCODER, ENCODER_OBJECTS, src, "cia408.encoder_eds")
    return valve, encoder


def position_step_nm(c: Cia408Config, valve_od: Any, encoder_od: Any, src: str) -> int:
    """The master's position step (nm): the encoder's measuring step 0x6005.1 from its EDS
    (start-up reads it again by SDO), or with ``position_source: valve`` the configured step of
    the valve's object, which must be an INTEGER32 the valve can map into its TPDO 2. A step
    coarser than the controller's position resolution is refused too."""
    if c.position_source == "encoder":
        step_nm, key = int(encoder_od[MEASURING_STEP][1].default or 0), "cia408.encoder_eds"
    else:
        key = "cia408.valve_position_object"
        index, sub = c.valve_position_object, c.valve_position_sub
        obj = valve_od.get_variable(index, sub) if index in valve_od else None
        if obj is None or obj.data_type != INTEGER32 or not obj.pdo_mappable:
            where = f"0x{index:04X}.{sub}"
            raise ConfigError(src, key, f"the valve EDS has no PDO-mappable INTEGER32 at {where}")
        if TPDO_COMM + 1 not in valve_od or TPDO_MAP + 1 not in valve_od:
            raise ConfigError(src, key, "the valve EDS has no TPDO 2 (0x1801/0x1A01) to carry it")
        step_nm, key = c.valve_position_step_nm, "cia408.valve_position_step_nm"
    if not 0 < step_nm * 1e-9 <= POSITION_RESOLUTION_M * (1 + 1e-9):
        raise ConfigError(
            src, key, f"position step {step_nm} nm (expected 1 … {POSITION_RESOLUTION_M * 1e9:g} nm)"
        )
    return step_nm
