"""A miswired valve for the bring-up checks (``firmware-sim --reverse …``).

A real installation gets signs wrong: the coil's two wires swapped at the amplifier, an LVDT or
a position transducer mounted or scaled the other way round. The emulator reproduces each so
that ``ehpss-hil bringup`` can be shown to find it (tests/test_bringup_processes.py):

* ``current``: the coil is driven with the opposite current; the amplifier's echo still reports
  the current it was told to apply (it measures its own output), so spool and piston move the
  other way while the echo looks right;
* ``spool``: the spool LVDT reads −x_v;
* ``position``: the piston position sensor reads −x.

The plant itself (and the truth, PLANT_TRUTH) is unchanged.
"""

from __future__ import annotations

from dataclasses import replace

from ehpss_hil.emulation import PlantEmulation, SensorSample
from ehpss_hil.physics.params import Params
from ehpss_hil.scenario import Scenario

#: what ``--reverse`` may name
REVERSIBLE = ("current", "spool", "position")


class MiswiredEmulation(PlantEmulation):
    """:class:`PlantEmulation` with the signals in ``reverse`` (of :data:`REVERSIBLE`) reversed."""

    def __init__(self, params: Params, scenario: Scenario, reverse: frozenset[str]) -> None:
        super().__init__(params, scenario)
        unknown = reverse - set(REVERSIBLE)
        if unknown:
            raise ValueError(f"cannot reverse {sorted(unknown)}; one of {REVERSIBLE}")
        self.reverse = reverse

    def measure(self) -> SensorSample:
        s = super().measure()
        rev = self.reverse
        return replace(
            s,
            position_m=-s.position_m if "position" in rev else s.position_m,
            spool_m=-s.spool_m if "spool" in rev else s.spool_m,
            coil_current_a=-s.coil_current_a if "current" in rev else s.coil_current_a,
        )

    def advance(self, current_a: float) -> float:
        if "current" not in self.reverse:
            return super().advance(current_a)
        return -super().advance(-current_a)


def make_emulation(params: Params, scenario: Scenario, reverse: list[str] | None) -> PlantEmulation:
    """The emulation of ``firmware-sim``: miswired when ``--reverse`` named anything."""
    if not reverse:
        return PlantEmulation(params, scenario)
    return MiswiredEmulation(params, scenario, frozenset(reverse))
