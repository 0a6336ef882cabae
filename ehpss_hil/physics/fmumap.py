"""The ``fmu_map`` of ``plant: {model: fmu}``: which variable of the user's FMU is which signal of
the bench, and what the bench expects of each (docs/fmu.md).

Each key is a bench signal named with its SI unit; its value is the FMU variable's name. The coil
current goes in; piston position, actual spool position and load pressure come out (the sensor,
noise, drift, bias, stuck and frame-loss layers stay ours, around the FMU); the coil-current echo
may come out (else the bench echoes the current it applied). The actuator faults k_LOE and k_Q
go in as gains (1 = healthy) when the map names them; a scenario that sets one the map does not
name is refused. The current limit is the bench's amplifier, applied before the FMU.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Literal

from ..errors import ConfigError


@dataclass(frozen=True)
class Signal:
    """What the bench expects of the FMU variable mapped to one signal."""

    #: ``input``: the bench sets it before each step; ``output``: the bench reads it after
    direction: Literal["input", "output"]
    #: the SI unit the variable must declare, if it declares one (``1``: dimensionless)
    unit: str


#: the bench's signals: key of ``fmu_map`` → what the FMU variable must be
SIGNALS: dict[str, Signal] = {
    "current_a": Signal("input", "A"),
    "position_m": Signal("output", "m"),
    "spool_m": Signal("output", "m"),
    "load_pressure_pa": Signal("output", "Pa"),
    "current_echo_a": Signal("output", "A"),
    "k_loe": Signal("input", "1"),
    "k_q": Signal("input", "1"),
}
#: the actuator faults an FMU may model: the FaultState field each ``fmu_map`` key sets
ACTUATOR_FAULTS: tuple[str, ...] = ("k_loe", "k_q")
#: the declared units accepted for each expected unit (FMI tools write a dimensionless one
#: as ``1`` or an empty string)
UNIT_SPELLINGS: dict[str, frozenset[str]] = {
    "A": frozenset({"A"}),
    "m": frozenset({"m"}),
    "Pa": frozenset({"Pa"}),
    "1": frozenset({"1", ""}),
}


@dataclass(frozen=True)
class FmuMap:
    """Bench signal → FMU variable name (``""``: not mapped; the first four are required)."""

    #: coil current the bench's amplifier applies over the sample (input, A)
    current_a: str
    #: piston position x (output, m)
    position_m: str
    #: actual spool displacement, what the spool LVDT measures (output, m)
    spool_m: str
    #: load pressure, what the pressure sensor measures (output, Pa)
    load_pressure_pa: str
    #: coil current the valve electronics report (output, A); unmapped: the applied current
    current_echo_a: str = ""
    #: spool loss-of-effectiveness gain (input, 1 = healthy); unmapped: faults refused
    k_loe: str = ""
    #: flow-gain factor (input, 1 = healthy); unmapped: faults refused
    k_q: str = ""

    def __post_init__(self) -> None:
        named: dict[str, str] = {}
        for f in fields(self):
            var = getattr(self, f.name)
            if var and var in named:
                raise ConfigError("", f.name, f"FMU variable {var!r} is mapped to {named[var]} already")
            if var:
                named[var] = f.name

    def mapped(self) -> dict[str, str]:
        """The mapped signals: bench key → FMU variable name."""
        return {f.name: v for f in fields(self) if (v := getattr(self, f.name))}

    @property
    def faults(self) -> frozenset[str]:
        """The actuator faults this map sends to the FMU (FaultState field names)."""
        return frozenset(k for k in ACTUATOR_FAULTS if getattr(self, k))
