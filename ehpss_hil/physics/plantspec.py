"""A scenario's ``plant:`` section: the emulated plant's own parameters (plant ≠ model).

Every key of ``params.yaml``'s ``plant:`` section may be given here as an absolute SI value; it
replaces that value for the emulated plant only (the controller, its models and y_m keep the
controller's params). ``model: nonlinear`` selects the valve-controlled single-rod cylinder of
:mod:`.hydraulics`, whose own keys are listed in :class:`PlantSpec` (each with its unit); they are
refused with ``model: linear``. Ranges are the same as in ``params.yaml`` (one home: the
metadata of :class:`~.params.PlantParams`). ``model: fmu`` runs the user's FMI co-simulation FMU
at ``path`` (relative to the scenario's folder) through ``fmu_map`` (:mod:`.fmumap`,
:mod:`.fmuplant`, docs/fmu.md); the FMU carries its own parameters, so no plant key goes with it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import asdict, dataclass, field, is_dataclass, replace
from pathlib import Path
from typing import Any, Literal

from ..errors import ConfigError
from ..schema import build, rng
from .fmumap import ACTUATOR_FAULTS, FmuMap
from .params import PlantParams

# the nonlinear plant's two pressure defaults live here, below :mod:`.hydraulics` (which reads
# them too): the spec's own check needs them

#: supply pressure P_S when the scenario gives none (Pa): a common industrial 210 bar
SUPPLY_PRESSURE_PA = 21e6
#: return pressure P_T when the scenario gives none (Pa, gauge)
RETURN_PRESSURE_PA = 0.0

#: the lumped keys of params.yaml's ``plant:`` section
LUMPED_KEYS = tuple(f.name for f in dataclasses.fields(PlantParams))


def _same_range(name: str) -> dict[str, Any]:
    """The range metadata of ``PlantParams.<name>`` (one home for it)."""
    return dict(next(f for f in dataclasses.fields(PlantParams) if f.name == name).metadata)


@dataclass(frozen=True)
class PlantSpec:
    """The emulated plant's parameters: overrides of params.yaml's plant keys (None: keep the
    base value) and the nonlinear model's keys (None: the default of :mod:`.hydraulics`, derived
    so that the nonlinear plant linearises to the lumped one; see docs/physics.md)."""

    model: Literal["linear", "nonlinear", "fmu"] = "linear"
    cylinder_damping_1_s: float | None = field(default=None, metadata=_same_range("cylinder_damping_1_s"))
    hydraulic_stiffness_1_s2: float | None = field(
        default=None, metadata=_same_range("hydraulic_stiffness_1_s2")
    )
    flow_gain_1_s3: float | None = field(default=None, metadata=_same_range("flow_gain_1_s3"))
    valve_damping_1_s: float | None = field(default=None, metadata=_same_range("valve_damping_1_s"))
    valve_stiffness_1_s2: float | None = field(default=None, metadata=_same_range("valve_stiffness_1_s2"))
    valve_gain_m_per_a_s2: float | None = field(default=None, metadata=_same_range("valve_gain_m_per_a_s2"))
    load_mass_kg: float | None = field(default=None, metadata=_same_range("load_mass_kg"))
    piston_area_m2: float | None = field(default=None, metadata=_same_range("piston_area_m2"))
    spool_stroke_m: float | None = field(default=None, metadata=_same_range("spool_stroke_m"))
    #: supply pressure P_S (Pa)
    supply_pressure_pa: float | None = field(default=None, metadata=rng(1e5, 1e8))
    #: return (tank) pressure P_T (Pa), below the supply
    return_pressure_pa: float | None = field(default=None, metadata=rng(0.0, 1e7))
    #: rod-side over cap-side piston area A_B/A_A (1 = double rod)
    area_ratio: float | None = field(default=None, metadata=rng(0.1, 1.0))
    #: Coulomb friction force F_c (N), smoothed as F_c·tanh(v/friction_velocity_m_s)
    coulomb_friction_n: float | None = field(default=None, metadata=rng(0.0, 1e5))
    #: velocity scale of the Coulomb friction's tanh (m/s)
    friction_velocity_m_s: float | None = field(default=None, metadata=rng(1e-6, 1.0))
    #: viscous friction B_v (N·s/m); the leakage is derived so the damping stays cylinder_damping
    viscous_friction_n_s_m: float | None = field(default=None, metadata=rng(0.0, 1e6))
    #: spool overlap u (m): the spool opens no orifice within ±u (a dead band); < the stroke
    spool_overlap_m: float | None = field(default=None, metadata=rng(0.0, 0.01))
    #: constant external force F_ext opposing extension (N)
    external_force_n: float | None = field(default=None, metadata=rng(-1e6, 1e6))
    #: load spring k (N/m) pulling the piston to x = 0
    spring_n_m: float | None = field(default=None, metadata=rng(0.0, 1e9))
    #: piston end stops at ±piston_stroke_m from the centre (m)
    piston_stroke_m: float | None = field(default=None, metadata=rng(0.0, 0.5, lo_open=True))
    #: oil beyond an end stop (chamber dead volume + hose) as a length of the bore (m)
    dead_length_m: float | None = field(default=None, metadata=rng(0.0, 1.0, lo_open=True))
    #: ``model: fmu``: the FMU file (absolute once the scenario is loaded)
    path: str = ""
    #: ``model: fmu``: bench signal → FMU variable (:class:`~.fmumap.FmuMap`)
    fmu_map: FmuMap | None = None

    def __post_init__(self) -> None:
        self._check_fmu_keys()
        if self.model == "linear":
            for key in NONLINEAR_KEYS:
                if getattr(self, key) is not None:
                    raise ConfigError("", key, "a key of the nonlinear plant: needs model: nonlinear")
        ps = SUPPLY_PRESSURE_PA if self.supply_pressure_pa is None else self.supply_pressure_pa
        pt = RETURN_PRESSURE_PA if self.return_pressure_pa is None else self.return_pressure_pa
        if pt >= ps:
            key = "return_pressure_pa" if self.return_pressure_pa is not None else "supply_pressure_pa"
            raise ConfigError("", key, f"the return pressure must be below the supply ({pt:g} >= {ps:g} Pa)")
        stroke, lap = self.spool_stroke_m, self.spool_overlap_m
        if lap is not None and lap >= (stroke if stroke is not None else PlantParams().spool_stroke_m):
            raise ConfigError("", "spool_overlap_m", "must be below the spool stroke")

    def _check_fmu_keys(self) -> None:
        """``path`` and ``fmu_map`` go with ``model: fmu`` and nothing else does."""
        if self.model != "fmu":
            for key in ("path", "fmu_map"):
                if getattr(self, key):
                    raise ConfigError("", key, "a key of the FMU plant: needs model: fmu")
            return
        for key in ("path", "fmu_map"):
            if not getattr(self, key):
                raise ConfigError("", key, "required with model: fmu")
        for key in (*LUMPED_KEYS, *NONLINEAR_KEYS):
            if getattr(self, key) is not None:
                raise ConfigError("", key, "the FMU carries its own plant parameters: not with model: fmu")

    def loaded(self, base_dir: Path | None = None, source: str = "") -> PlantSpec:
        """This section with an FMU's ``path`` made absolute (relative to ``base_dir``, the folder
        of the file naming it) and the FMU checked against ``fmu_map`` (:func:`.fmuplant.check_fmu`:
        ConfigError naming ``plant.path`` or ``plant.fmu_map.<key>`` in ``source``); else itself."""
        if self.model != "fmu":
            return self
        from .fmuplant import check_fmu  # fmpy: only for an FMU plant

        p = Path(self.path)
        if not p.is_absolute() and base_dir is not None:
            p = base_dir / p
        spec = replace(self, path=str(p.absolute()))
        assert spec.fmu_map is not None
        check_fmu(Path(spec.path), spec.fmu_map, source)
        return spec

    def fmu_digest(self) -> str:
        """SHA-256 (hex) of the FMU file's bytes (``model: fmu``; "" otherwise)."""
        if self.model != "fmu":
            return ""
        import hashlib

        return hashlib.sha256(Path(self.path).read_bytes()).hexdigest()

    @property
    def modelled_faults(self) -> frozenset[str]:
        """The actuator faults (FaultState fields) this plant models: all for the built-in
        plants, those ``fmu_map`` names for an FMU."""
        if self.model == "fmu" and self.fmu_map is not None:
            return self.fmu_map.faults
        return frozenset(ACTUATOR_FAULTS)

    @property
    def lumped_overrides(self) -> dict[str, float]:
        """The params.yaml keys this section sets (absolute SI values)."""
        return {k: v for k in LUMPED_KEYS if (v := getattr(self, k)) is not None}

    def plant_params(self, base: PlantParams) -> PlantParams:
        """``base`` (the emulator's params.yaml plant) with this section's lumped keys."""
        over = self.lumped_overrides
        return replace(base, **over) if over else base

    @property
    def is_nominal(self) -> bool:
        """True when the section changes nothing (linear model, no override)."""
        return self == PlantSpec()

    def validated(self) -> PlantSpec:
        """This section checked like a file's (ranges included: a section built in code, such
        as a campaign's sampled plant, gets no range check otherwise); ConfigError naming the
        key."""
        data = {
            f.name: asdict(v) if is_dataclass(v) and not isinstance(v, type) else v
            for f in dataclasses.fields(self)
            if (v := getattr(self, f.name)) is not None
        }
        return build(PlantSpec, data)

    def describe(self) -> str:
        """``linear``, or ``nonlinear, flow_gain_1_s3 1.134e+08, area_ratio 0.6`` (keys set)."""
        if self.model == "fmu":
            return f"fmu {Path(self.path).name}"
        keys = [f"{k} {v:g}" for k in (*LUMPED_KEYS, *NONLINEAR_KEYS) if (v := getattr(self, k)) is not None]
        return ", ".join([self.model, *keys])


#: the keys only the nonlinear plant reads
NONLINEAR_KEYS = tuple(
    f.name
    for f in dataclasses.fields(PlantSpec)
    if f.name not in ("model", "path", "fmu_map") and f.name not in LUMPED_KEYS
)
