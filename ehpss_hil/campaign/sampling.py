"""Run index → scenario: the campaign's points in the unit hypercube mapped to faults, reference,
noise and seed (docs/campaigns.md).

Everything a run is made of comes from the campaign's content hash and the run's index alone:
the sampler's seed is taken from the hash, all points are drawn at once in the main process
(``random``: numpy's PCG64; ``lhs``/``sobol``: :mod:`scipy.stats.qmc`, scrambled), and a run's
scenario seed is a hash of (content hash, index). Workers receive finished scenarios, so the
table cannot depend on which worker ran what, or in which order.

Dimensions of a point: the number of faults; per fault slot its kind, magnitude, onset, whether
it ramps and the ramp's duration; per plant key of ``model_error`` its relative error; the
reference's kind, amplitude and frequency; the noise scale.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import qmc

from ..errors import ConfigError
from ..physics.load import load_params
from ..physics.plantspec import PlantSpec
from ..scenario import Event, Noise, Reference, Scenario
from .scenario_file import scenario_data
from .spec import FAULT_KINDS, RAMPABLE, Campaign, canonical_json

#: a ramping fault reaches its magnitude in this many equal steps (the scenario schema has
#: step events only: a ramp is a staircase of them)
RAMP_STEPS = 10
#: sampled times (s) are rounded to this many decimals (0.1 ms, a tenth of the 1 ms sample time)
TIME_DECIMALS = 4
#: per fault kind: the scenario event key it sets, its healthy value, its fixed faulty value
#: (None: drawn from the kind's magnitude range)
FAULT_KEYS: dict[str, tuple[str, float | bool, float | bool | None]] = {
    "loe": ("k_loe", 1.0, None),
    "kq": ("k_q", 1.0, None),
    "drift": ("k_dft", 1.0, None),
    "sensor_failure": ("k_dft", 1.0, 0.0),
    "bias": ("position_bias_m", 0.0, None),
    "stuck": ("stuck", False, True),
    "frame_loss": ("frame_loss", 0.0, None),
}
_SLOT_DIMS = 5
_TAIL_DIMS = 4


@dataclass(frozen=True)
class Fault:
    """One sampled fault: kind, faulty value (gain, m, probability; 1.0 for ``stuck``), onset
    and ramp duration (s; 0 = abrupt)."""

    kind: str
    magnitude: float
    onset_s: float
    ramp_s: float


@dataclass(frozen=True)
class RunPlan:
    """One run of a campaign: index, sampled faults and scenario, content hash (hex)."""

    index: int
    faults: tuple[Fault, ...]
    noise_scale: float
    scenario: Scenario
    run_hash: str
    #: the emulated plant's relative error per sampled key (``model_error``), in key order
    model_error: tuple[tuple[str, float], ...] = ()

    @property
    def fault_class(self) -> str:
        """The run's fault kinds joined by ``+`` in sorted order (``none`` without a fault)."""
        return "+".join(sorted(f.kind for f in self.faults)) or "none"

    def parameters(self) -> dict[str, Any]:
        """The sampled parameters as table columns (NaN for a kind the run does not have)."""
        row: dict[str, Any] = {
            "index": self.index,
            "run_hash": self.run_hash,
            "fault_class": self.fault_class,
            "n_faults": len(self.faults),
        }
        by_kind = {f.kind: f for f in self.faults}
        for kind in FAULT_KINDS:
            f = by_kind.get(kind)
            row[f"{kind}.magnitude"] = f.magnitude if f else math.nan
            row[f"{kind}.onset_s"] = f.onset_s if f else math.nan
            row[f"{kind}.ramp_s"] = f.ramp_s if f else math.nan
        ref = self.scenario.reference
        row["reference_kind"] = ref.kind
        row["reference_amplitude_m"] = ref.amplitude_m
        row["reference_omega_rad_s"] = ref.omega_rad_s
        row["noise_scale"] = self.noise_scale
        row["seed"] = self.scenario.seed
        for key, rel in self.model_error:
            row[f"model_error.{key}"] = rel
        return row


def _sampler_seed(content_hash: str) -> int:
    return int(content_hash[:16], 16)


def unit_points(sampler: str, n: int, d: int, seed: int) -> np.ndarray:
    """``n`` points in [0, 1)^d from ``sampler`` (random | lhs | sobol), seeded."""
    gen = np.random.default_rng(seed)
    if sampler == "random":
        return gen.random((n, d))
    engine = qmc.LatinHypercube(d, rng=gen) if sampler == "lhs" else qmc.Sobol(d, rng=gen)
    with warnings.catch_warnings():  # Sobol's balance warning for n not a power of 2
        warnings.simplefilter("ignore", UserWarning)
        return np.asarray(engine.random(n))


def _lerp(lo_hi: tuple[float, ...], u: float) -> float:
    lo, hi = lo_hi
    return float(lo + (hi - lo) * u)


def _pick(weights: dict[str, float], u: float) -> str:
    """The kind whose share of the cumulative weight holds ``u``."""
    total = sum(weights.values())
    acc = 0.0
    for kind, w in weights.items():
        acc += w / total
        if u < acc:
            return kind
    return next(k for k in reversed(weights) if weights[k] > 0)


def _faults(camp: Campaign, point: np.ndarray) -> tuple[Fault, ...]:
    plan = camp.spec.faults
    lo, hi = plan.count
    n = min(lo + int(point[0] * (hi - lo + 1)), hi)
    weights = {k: w for k, w in plan.kinds.weights().items() if w > 0}
    out: list[Fault] = []
    for j in range(n):
        u_kind, u_mag, u_on, u_ramps, u_ramp = point[1 + _SLOT_DIMS * j : 1 + _SLOT_DIMS * (j + 1)]
        kind = _pick(weights, float(u_kind))
        del weights[kind]
        fixed = FAULT_KEYS[kind][2]
        mag = float(fixed) if fixed is not None else _lerp(plan.kinds.magnitude(kind), float(u_mag))
        onset = round(_lerp(plan.onset_s, float(u_on)), TIME_DECIMALS)
        ramps = kind in RAMPABLE and float(u_ramps) < plan.ramp_share
        ramp = round(_lerp(plan.ramp_s, float(u_ramp)), TIME_DECIMALS) if ramps else 0.0
        out.append(Fault(kind, mag, onset, ramp))
    return tuple(out)


def fault_events(faults: tuple[Fault, ...], duration_s: float) -> tuple[Event, ...]:
    """Scenario events of ``faults`` in time order (a ramp as :data:`RAMP_STEPS` steps from the
    healthy value; steps after ``duration_s`` dropped). Where two faults set the same key
    (drift and sensor failure: k_DFT), the later event holds."""
    timed: list[tuple[float, int, Event]] = []
    for i, f in enumerate(faults):
        key, healthy, _fixed = FAULT_KEYS[f.kind]
        target: float | bool = True if f.kind == "stuck" else f.magnitude
        steps = RAMP_STEPS if f.ramp_s > 0.0 else 1
        for s in range(1, steps + 1):
            t = round(f.onset_s + f.ramp_s * s / steps, TIME_DECIMALS)
            if t > duration_s:
                break
            value = (
                target
                if s == steps or isinstance(target, bool)
                else (float(healthy) + (float(target) - float(healthy)) * s / steps)
            )
            kwargs: dict[str, Any] = {key: value}
            timed.append((t, i, Event(t_s=t, **kwargs)))
    timed.sort(key=lambda e: (e[0], e[1]))
    return tuple(ev for _t, _i, ev in timed)


def _reference(camp: Campaign, u: np.ndarray) -> Reference:
    dist = camp.spec.reference
    if dist is None:
        return camp.base.reference
    kind = dist.kinds[min(int(u[0] * len(dist.kinds)), len(dist.kinds) - 1)]
    a = _lerp(dist.amplitude_m, float(u[1]))
    w = _lerp(dist.omega_rad_s, float(u[2]))
    # trapezoid: ramps take half of each half period (rate = 4·a·ω/π)
    return Reference(kind=kind, amplitude_m=a, omega_rad_s=w, rate_m_s=min(4.0 * a * w / math.pi, 1.0))


def _scaled(noise: Noise, k: float) -> Noise:
    return Noise(
        position_m=noise.position_m * k, spool_m=noise.spool_m * k, pressure_pa=noise.pressure_pa * k
    )


def run_seed(content_hash: str, index: int) -> int:
    """The scenario seed of run ``index`` (32 bits of a hash of campaign and index)."""
    return int(hashlib.sha256(f"{content_hash}:{index}".encode()).hexdigest()[:8], 16)


def _model_ranges(camp: Campaign) -> dict[str, tuple[float, float]]:
    me = camp.spec.model_error
    return me.ranges() if me is not None else {}


def dimensions(camp: Campaign) -> int:
    """Dimensions of a point (see the module docstring)."""
    return 1 + _SLOT_DIMS * camp.spec.faults.count[1] + len(_model_ranges(camp)) + _TAIL_DIMS


def _plant(camp: Campaign, u: np.ndarray, index: int) -> tuple[PlantSpec, tuple[tuple[str, float], ...]]:
    """The run's plant: the base scenario's, each ``model_error`` key moved by its relative
    error drawn from ``u`` (one coordinate per key), and the error per key."""
    me = camp.spec.model_error
    if me is None:
        return camp.base.plant, ()
    base = camp.base.plant.plant_params(load_params().plant)
    errors = tuple((k, _lerp(r, float(x))) for (k, r), x in zip(me.ranges().items(), u, strict=True))
    values = {k: getattr(base, k) * (1.0 + e) for k, e in errors}
    model = me.model or camp.base.plant.model
    try:
        plant = replace(camp.base.plant, model=model, **values).validated()
    except ConfigError as exc:
        raise ConfigError(camp.source, f"model_error.{exc.key_path}", f"run {index}: {exc.reason}") from exc
    return plant, errors


def plan_runs(camp: Campaign, draw: int | None = None) -> list[RunPlan]:
    """Every run of the campaign, in index order; with ``draw``: the runs of a draw of only
    that many points (``check-config`` builds a few, whatever ``samples`` is; with ``random``
    and ``sobol`` they are the campaign's first runs)."""
    spec = camp.spec
    n = spec.samples if draw is None else min(draw, spec.samples)
    pts = unit_points(spec.sampler, n, dimensions(camp), _sampler_seed(camp.content_hash))
    duration = camp.duration_s
    plans = []
    first_model_dim = 1 + _SLOT_DIMS * spec.faults.count[1]
    n_model = len(_model_ranges(camp))
    for i, p in enumerate(pts):
        faults = _faults(camp, p)
        plant, model_error = _plant(camp, p[first_model_dim : first_model_dim + n_model], i)
        tail = p[-_TAIL_DIMS:]
        k = _lerp(spec.noise_scale, float(tail[3]))
        sc = replace(
            camp.base,
            name=f"{spec.name}-{i:05d}",
            description=f"campaign {spec.name} run {i}: "
            + (", ".join(_describe(f) for f in faults) or "no fault"),
            duration_s=duration,
            seed=run_seed(camp.content_hash, i),
            reference=_reference(camp, tail[:3]),
            noise=_scaled(camp.base.noise, k),
            events=fault_events(faults, duration),
            plant=plant,
        )
        key = {"scenario": scenario_data(sc), "modes": list(spec.modes), "transport": spec.transport}
        digest = hashlib.sha256(canonical_json(key).encode()).hexdigest()
        plans.append(RunPlan(i, faults, k, sc, digest, model_error))
    return plans


def _describe(f: Fault) -> str:
    ramp = f" ramped over {f.ramp_s:g} s" if f.ramp_s > 0 else ""
    return f"{f.kind} {f.magnitude:.4g} at {f.onset_s:g} s{ramp}"
