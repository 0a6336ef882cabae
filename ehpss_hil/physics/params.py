"""Physical and controller parameters (SI) as dataclasses; :mod:`.load` reads them from a YAML
file (default: the shipped ``ehpss_hil/data/params.yaml``, linked as ``configs/params.yaml`` in
the repository) and checks them against :mod:`.model`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .. import DATA_DIR
from ..schema import rng

#: the shipped parameters (package data; ``configs/params.yaml`` in the repository links to it)
DEFAULT_PARAMS = DATA_DIR / "params.yaml"
#: a plant coefficient or the gains K_f, K_a may differ from the paper's eq 39 value by at most
#: this factor either way: beyond it the model is no EHPSS of this kind (and far enough beyond,
#: its exact discretization and the adaptive layer's scales overflow)
PARAM_RANGE_FACTOR = 1000.0


def _around(nominal: float) -> dict[str, Any]:
    """Range metadata: within :data:`PARAM_RANGE_FACTOR` of the paper's ``nominal`` value."""
    return rng(nominal / PARAM_RANGE_FACTOR, nominal * PARAM_RANGE_FACTOR)


@dataclass(frozen=True)
class PlantParams:
    """Servo valve + cylinder coefficients of the paper's eq 39 (SI units, see each name)."""

    cylinder_damping_1_s: float = field(default=2576.0, metadata=_around(2576.0))
    hydraulic_stiffness_1_s2: float = field(default=3.136e7, metadata=_around(3.136e7))
    flow_gain_1_s3: float = field(default=1.031e8, metadata=_around(1.031e8))
    valve_damping_1_s: float = field(default=3402.0, metadata=_around(3402.0))
    valve_stiffness_1_s2: float = field(default=5.905e6, metadata=_around(5.905e6))
    valve_gain_m_per_a_s2: float = field(default=9.739e7, metadata=_around(9.739e7))
    load_mass_kg: float = field(default=20.0, metadata=_around(20.0))
    piston_area_m2: float = field(default=2.206e-4, metadata=_around(2.206e-4))
    #: mechanical stroke of the spool, ±spool_stroke_m (m): the actual spool k_LOE·x_v stops
    #: there and the flow saturates. The spool LVDT's range (the DBC's Spool signal, ±10 mm)
    #: covers it: a reading at the stroke is the real spool, held at its stop.
    spool_stroke_m: float = field(default=0.01, metadata=rng(0.0, 0.01, lo_open=True))

    @property
    def velocity_gain_1_s(self) -> float:
        """K_c: steady piston velocity per metre of spool, flow_gain / hydraulic_stiffness (1/s)."""
        return self.flow_gain_1_s3 / self.hydraulic_stiffness_1_s2

    @property
    def piston_speed_max_m_s(self) -> float:
        """The fastest steady piston speed (m/s): K_c × the spool stroke (the spool at its stop)."""
        return self.velocity_gain_1_s * self.spool_stroke_m

    @property
    def valve_static_gain_m_per_a(self) -> float:
        """Steady spool displacement per ampere of coil current (m/A)."""
        return self.valve_gain_m_per_a_s2 / self.valve_stiffness_1_s2

    @property
    def stroke_current_a(self) -> float:
        """The steady coil current that moves the spool to its stroke (A): the command range a
        valve's current field must hold either way."""
        return self.spool_stroke_m / self.valve_static_gain_m_per_a


@dataclass(frozen=True)
class ControllerGains:
    """PI gains of eq 39: ``e = K_f·x_d − y_f``, ``z' = K_i·e``, ``I = K_a·(K_p·e + K_i·z)``."""

    k_f: float = field(default=12.71, metadata=_around(12.71))
    k_p: float = field(default=4.0, metadata=rng(0.0, 1e3))
    k_i: float = field(default=2.0, metadata=rng(0.0, 1e3))
    k_a: float = field(default=0.0861, metadata=_around(0.0861))


@dataclass(frozen=True)
class Params:
    """Everything ``configs/params.yaml`` holds (read and checked by
    :func:`~ehpss_hil.physics.load.load_params`)."""

    plant: PlantParams = field(default_factory=PlantParams)
    controller: ControllerGains = field(default_factory=ControllerGains)
