"""Campaign files: a base scenario plus the distributions runs are sampled from (docs/campaigns.md).

Read like every other input file (:func:`~ehpss_hil.inputfile.load_yaml`: size, depth, node and
time caps, no aliases) and built by :func:`~ehpss_hil.schema.build`: an unknown key, wrong type or
out-of-range value is a one-line :class:`~ehpss_hil.errors.ConfigError` naming file and key path.

A range is a two-item list ``[low, high]`` (``low <= high``; equal items fix the value). Fault
kinds are those the scenario schema injects: ``loe`` (k_LOE), ``kq`` (k_Q), ``drift`` (k_DFT),
``sensor_failure`` (k_DFT = 0), ``bias`` (position sensor bias, m), ``stuck`` (position sensor
frozen) and ``frame_loss`` (both directions); a kind absent from ``faults.kinds`` is never drawn.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from ..control.registry import MODES
from ..control.tuning import ControlTuning
from ..errors import ConfigError
from ..limits import MAX_CAMPAIGN_RUNS, MAX_FAULTS_PER_RUN, MAX_REFERENCE_M
from ..physics.plantspec import LUMPED_KEYS
from ..scenario import Scenario, load_scenario
from ..schema import build, load_yaml, rng

#: the modes every campaign runs: the summary compares mmac with nrc (harm) and oracle (compensated)
REQUIRED_MODES = ("nrc", "mmac", "oracle")
#: fault kinds in the order the sampler draws their dimensions
FAULT_KINDS = ("loe", "kq", "drift", "sensor_failure", "bias", "stuck", "frame_loss")
#: kinds whose magnitude can ramp in (incipient faults); the others change at once
RAMPABLE = ("loe", "kq", "drift", "bias", "frame_loss")
#: a campaign's name: one folder name (``runs/campaign-<name>``), never a path
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


def _pair(lo: float | None, hi: float | None, doc: str, *, lo_open: bool = False) -> dict[str, Any]:
    return rng(lo, hi, lo_open=lo_open, length=(2, 2), doc=doc)


def _ordered(obj: object, *keys: str) -> None:
    for key in keys:
        lo, hi = getattr(obj, key)
        if lo > hi:
            raise ConfigError("", key, f"expected [low, high] with low <= high, got [{lo}, {hi}]")


@dataclass(frozen=True)
class KindDist:
    """One fault kind: its weight when kinds are drawn, and its magnitude range (the kind's unit:
    a gain for loe/kq/drift, metres for bias, a loss probability for frame_loss; sensor_failure
    and stuck have none)."""

    weight: float = field(default=1.0, metadata=rng(0.0, 1e6))
    #: None: the kind's :data:`DEFAULT_MAGNITUDE`
    magnitude: tuple[float, ...] | None = field(default=None, metadata=_pair(-0.1, 2.5, "kind's unit"))


#: allowed magnitude per kind (inclusive bounds; the scenario schema's own ranges)
MAGNITUDE_BOUNDS: dict[str, tuple[float, float]] = {
    "loe": (1e-3, 1.5),
    "kq": (1e-3, 1.5),
    "drift": (0.0, 2.5),
    "bias": (-0.1, 0.1),
    "frame_loss": (0.0, 1.0),
}
#: magnitude range of a kind whose entry gives none
DEFAULT_MAGNITUDE: dict[str, tuple[float, float]] = {
    "loe": (0.3, 0.9),
    "kq": (0.5, 0.9),
    "drift": (0.5, 1.5),
    "bias": (-2e-4, 2e-4),
    "frame_loss": (0.01, 0.2),
}


@dataclass(frozen=True)
class FaultKinds:
    """The fault kinds that may be drawn (absent: weight 0, never drawn)."""

    loe: KindDist | None = None
    kq: KindDist | None = None
    drift: KindDist | None = None
    sensor_failure: KindDist | None = None
    bias: KindDist | None = None
    stuck: KindDist | None = None
    frame_loss: KindDist | None = None

    def __post_init__(self) -> None:
        for kind in FAULT_KINDS:
            dist = getattr(self, kind)
            if dist is None or dist.magnitude is None:
                continue
            if kind not in MAGNITUDE_BOUNDS:
                raise ConfigError("", f"{kind}.magnitude", "this fault kind has no magnitude")
            lo, hi = dist.magnitude
            blo, bhi = MAGNITUDE_BOUNDS[kind]
            if not (blo <= lo <= hi <= bhi):
                raise ConfigError(
                    "", f"{kind}.magnitude", f"expected low <= high within [{blo}, {bhi}], got [{lo}, {hi}]"
                )

    def weights(self) -> dict[str, float]:
        """Weight per kind (0 for an absent kind), in :data:`FAULT_KINDS` order."""
        return {k: (d.weight if (d := getattr(self, k)) is not None else 0.0) for k in FAULT_KINDS}

    def magnitude(self, kind: str) -> tuple[float, float]:
        """The magnitude range of ``kind`` (its default when the file gives none)."""
        dist = getattr(self, kind)
        if dist is None or dist.magnitude is None:
            return DEFAULT_MAGNITUDE.get(kind, (0.0, 0.0))
        return (dist.magnitude[0], dist.magnitude[1])


@dataclass(frozen=True)
class FaultPlan:
    """How many faults a run gets (distinct kinds), when they start (s) and how they ramp in."""

    kinds: FaultKinds = field(default_factory=FaultKinds)
    count: tuple[int, ...] = field(default=(1, 1), metadata=_pair(0, MAX_FAULTS_PER_RUN, "faults per run"))
    onset_s: tuple[float, ...] = field(default=(0.5, 1.5), metadata=_pair(0.0, 86400.0, "s"))
    #: ramp duration (s) of a ramping fault: its magnitude moves from healthy in a staircase
    ramp_s: tuple[float, ...] = field(default=(0.0, 0.0), metadata=_pair(0.0, 86400.0, "s"))
    #: probability that a rampable fault ramps in (else it is abrupt)
    ramp_share: float = field(default=0.0, metadata=rng(0.0, 1.0))

    def __post_init__(self) -> None:
        _ordered(self, "count", "onset_s", "ramp_s")
        n_kinds = sum(w > 0 for w in self.kinds.weights().values())
        if self.count[1] > n_kinds:
            raise ConfigError(
                "",
                "count",
                f"up to {self.count[1]} faults at once but only {n_kinds} kind(s) with weight > 0",
            )


@dataclass(frozen=True)
class ReferenceDist:
    """Reference motions drawn per run: kind, amplitude (m), angular frequency (rad/s)."""

    kinds: tuple[Literal["sine", "square", "trapezoid"], ...] = field(
        default=("sine",), metadata=rng(length=(1, 3))
    )
    amplitude_m: tuple[float, ...] = field(default=(0.001, 0.001), metadata=_pair(1e-6, MAX_REFERENCE_M, "m"))
    omega_rad_s: tuple[float, ...] = field(default=(5.0, 5.0), metadata=_pair(0.1, 200.0, "rad/s"))

    def __post_init__(self) -> None:
        _ordered(self, "amplitude_m", "omega_rad_s")


#: a sampled plant key stays within ±this relative error of the base plant's value
MAX_RELATIVE_MODEL_ERROR = 0.9


def _relative(doc: str) -> dict[str, Any]:
    return _pair(-MAX_RELATIVE_MODEL_ERROR, MAX_RELATIVE_MODEL_ERROR, doc)


@dataclass(frozen=True)
class ModelError:
    """Plant ≠ model in every run: the emulated plant's keys drawn uniformly as relative errors
    ``[low, high]`` around the base scenario's plant (``[-0.2, 0.2]``: ±20 %), and optionally its
    ``model``; the controller keeps configs/params.yaml (docs/campaigns.md)."""

    model: Literal["linear", "nonlinear"] | None = None
    cylinder_damping_1_s: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    hydraulic_stiffness_1_s2: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    flow_gain_1_s3: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    valve_damping_1_s: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    valve_stiffness_1_s2: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    valve_gain_m_per_a_s2: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    load_mass_kg: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    piston_area_m2: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))
    spool_stroke_m: tuple[float, ...] | None = field(default=None, metadata=_relative("relative"))

    def __post_init__(self) -> None:
        _ordered(self, *self.ranges())

    def ranges(self) -> dict[str, tuple[float, float]]:
        """The relative range of each plant key drawn, in params.yaml's key order."""
        return {k: (r[0], r[1]) for k in LUMPED_KEYS if (r := getattr(self, k)) is not None}


@dataclass(frozen=True)
class CampaignSpec:
    """A campaign file. ``base`` is a scenario file (relative to the campaign file); its events
    are replaced by the sampled faults, its reference by ``reference`` when given, its noise
    scaled by a factor drawn from ``noise_scale``, its seed by one derived per run."""

    name: str
    base: str
    samples: int = field(metadata=rng(1, MAX_CAMPAIGN_RUNS))
    sampler: Literal["random", "lhs", "sobol"] = "sobol"
    #: mixed into the campaign's content hash: change it for another draw of the same file
    seed: int = field(default=0, metadata=rng(0, 2**63 - 1))
    modes: tuple[str, ...] = field(default=REQUIRED_MODES, metadata=rng(length=(3, len(MODES))))
    duration_s: float | None = field(default=None, metadata=rng(0.0, 86400.0, lo_open=True))
    transport: Literal["quantize", "frames"] = "quantize"
    faults: FaultPlan = field(default_factory=FaultPlan)
    reference: ReferenceDist | None = None
    noise_scale: tuple[float, ...] = field(default=(1.0, 1.0), metadata=_pair(0.0, 100.0, "factor"))
    #: the emulated plant's error against the controller's model, drawn per run
    model_error: ModelError | None = None
    #: the controller's tuning in every run (keys of ControlTuning, validated like a controller
    #: config's ``tuning:``; absent keys keep their defaults), e.g. a commissioned controller's
    #: ``pressure_gain_uncertainty: 0`` where the plant is the controller's model
    tuning: ControlTuning = field(default_factory=ControlTuning)
    description: str = ""

    def __post_init__(self) -> None:
        if not NAME_PATTERN.fullmatch(self.name):
            raise ConfigError(
                "",
                "name",
                "expected 1-64 letters, digits, '.', '_' or '-', starting with a letter or digit "
                "(it names the folder runs/campaign-<name>)",
            )
        _ordered(self, "noise_scale")
        for i, m in enumerate(self.modes):
            if m not in MODES:
                raise ConfigError("", f"modes[{i}]", f"unknown mode {m!r}; choose from {', '.join(MODES)}")
        missing = [m for m in REQUIRED_MODES if m not in self.modes]
        if missing or len(set(self.modes)) != len(self.modes):
            raise ConfigError(
                "", "modes", f"must name {', '.join(REQUIRED_MODES)} once each (missing {missing})"
            )


@dataclass(frozen=True)
class Campaign:
    """A loaded campaign: its spec, base scenario and content hash (hex)."""

    spec: CampaignSpec
    base: Scenario
    source: str
    content_hash: str

    @property
    def duration_s(self) -> float:
        """Duration of every run (s)."""
        return self.spec.duration_s if self.spec.duration_s is not None else self.base.duration_s


def tuning_overrides(tuning: ControlTuning) -> str:
    """The tuning keys that differ from the defaults, as ``key value, …`` ("" when none)."""
    base = ControlTuning()
    return ", ".join(
        f"{f.name} {getattr(tuning, f.name)!r}"
        for f in dataclasses.fields(tuning)
        if getattr(tuning, f.name) != getattr(base, f.name)
    )


def canonical_json(data: Any) -> str:
    """``data`` as compact JSON with sorted keys: the text every content hash is taken over."""
    return json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)


#: the campaign fault kinds that are actuator faults: kind → the FaultState field it sets
ACTUATOR_KINDS = {"loe": "k_loe", "kq": "k_q"}


def _check_fmu_faults(spec: CampaignSpec, base: Scenario, source: str) -> None:
    """An actuator fault kind the base scenario's plant does not model (an FMU whose
    ``fmu_map`` does not name it) cannot be drawn: ConfigError naming ``faults.kinds.<kind>``."""
    for kind, key in ACTUATOR_KINDS.items():
        if getattr(spec.faults.kinds, kind) is not None and key not in base.plant.modelled_faults:
            raise ConfigError(
                source,
                f"faults.kinds.{kind}",
                f"the base scenario's FMU plant does not model {key} (no plant.fmu_map.{key})",
            )


def load_campaign(path: str | Path, data: object = None) -> Campaign:
    """Load and validate a campaign file (``data``: its parsed content, when the caller read it
    already) and its base scenario. The content hash covers the parsed campaign (not its comments
    or layout, and not where its base scenario lives: ``base`` is left out) and the parsed base
    scenario, so a campaign draws the same runs in any checkout."""
    p = Path(path)
    if data is None:
        data = load_yaml(p)
    spec = build(CampaignSpec, data, str(p))
    base_path = p.parent / spec.base
    base_data = load_yaml(base_path)
    base = load_scenario(base_path, base_data)
    if spec.faults.onset_s[1] > (spec.duration_s or base.duration_s):
        raise ConfigError(str(p), "faults.onset_s", "onsets must lie within the run's duration_s")
    _check_fmu_faults(spec, base, str(p))
    own = {k: v for k, v in data.items() if k != "base"} if isinstance(data, dict) else data
    hashed = {"campaign": own, "base": base_data}
    if base.plant.model == "fmu":  # a changed FMU is another campaign (resumed runs are not reused)
        hashed["fmu_sha256"] = base.plant.fmu_digest()
    digest = hashlib.sha256(canonical_json(hashed).encode()).hexdigest()
    return Campaign(spec, base, str(p), digest)
