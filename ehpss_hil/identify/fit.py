"""Fit params.yaml's plant keys to an identification record: ``scipy.optimize.least_squares``
on the simulated response of the linear model structure (:func:`~ehpss_hil.physics.model.plant_matrices`,
exact ZOH at the sample time — the structure the controller's models use).

Why least squares on the simulated response (output error) rather than a subspace or ARX fit:
the parameters we need are the physical coefficients of one known 5-state structure, and the
valve (ω_sv ≈ 390 Hz) and hydraulic (ω_h ≈ 890 Hz) resonances lie near or above Nyquist at 1 kHz,
where a black-box discrete model cannot be mapped back to them reliably; the exact ZOH map of the
structure can. The input (the current echo) is measured, so the output error is the sensor noise
and the fit is consistent inside the closed loop. least_squares is scipy's maintained
trust-region solver with bounds and a Jacobian at the solution, from which the intervals come.

Parameters (θ): the log of each fitted key relative to its start value, a current offset (the
spool null offset, as the coil current that centres the spool, A), the position sensor's zero
(m) and the pressure sensor's zero (Pa; a single-rod cylinder at rest holds a load pressure).
Residuals: position, spool LVDT and load pressure, each divided by its channel's noise level
(first pass: its signal RMS; second pass: its residual RMS). Covariance ``(JᵀJ)⁻¹·σ²`` with σ² the
reduced χ² of the weighted residuals; intervals are 95 % (±1.96 standard deviations).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..physics.discretize import zoh
from ..physics.load import check_closed_loop_stable
from ..physics.model import ACC, POS, SPOOL, plant_matrices
from ..physics.params import Params, PlantParams
from .experiment import Record

Array = NDArray[np.float64]

#: the plant keys the fit estimates (the others — mass, area, stroke — stay as given)
FITTED_KEYS = (
    "valve_gain_m_per_a_s2",
    "valve_stiffness_1_s2",
    "valve_damping_1_s",
    "flow_gain_1_s3",
    "hydraulic_stiffness_1_s2",
    "cylinder_damping_1_s",
)
#: two-sided 95 % normal quantile for the intervals
Z95 = 1.959964
#: bound on |log(value / start value)|: the fit searches within a factor e² either way
LOG_BOUND = 2.0
#: offsets fitted beside the keys: current (µA), position zero (µm), pressure zero (kPa)
N_OFFSETS = 3
#: channels of a record, in residual order
CHANNELS = ("position_m", "spool_m", "load_pressure_pa")


@dataclass(frozen=True)
class Estimate:
    """One identified quantity: value, 95 % interval half-width relative to it, unit."""

    name: str
    value: float
    rel_ci95: float
    unit: str


@dataclass(frozen=True)
class FitResult:
    """The fitted params (the start params with :data:`FITTED_KEYS` replaced), every estimate
    with its interval, the offsets, the residual RMS per channel and the solver's counts."""

    params: Params
    keys: tuple[Estimate, ...]
    derived: tuple[Estimate, ...]
    spool_null_offset_m: Estimate
    position_zero_m: Estimate
    residual_rms: dict[str, float]
    evaluations: int

    def estimate(self, name: str) -> Estimate:
        """The key or derived quantity called ``name``."""
        return next(e for e in (*self.keys, *self.derived) if e.name == name)


def simulate(plant: PlantParams, applied_a: Array, ts_s: float, current_offset_a: float = 0.0) -> Array:
    """Outputs ``[x, x_v, P_L]`` (m, m, Pa) at every sample of the linear plant from rest, with
    ``applied_a[k] + current_offset_a`` held over [k, k+1)."""
    a, b = plant_matrices(plant)
    ad, bd = zoh(a, b, ts_s)
    n = len(applied_a)
    u = np.nan_to_num(applied_a) + current_offset_a
    xs = np.empty((n, 5))
    x = np.zeros(5)
    bcol = bd[:, 0]
    for k in range(n):
        xs[k] = x
        x = ad @ x + bcol * u[k]
    p_per_acc = plant.load_mass_kg / plant.piston_area_m2
    return np.column_stack((xs[:, POS], xs[:, SPOOL], p_per_acc * xs[:, ACC]))


def _measured(rec: Record) -> Array:
    return np.column_stack([getattr(rec, c) for c in CHANNELS])


class _Problem:
    """The residual function of θ = (log ratios of :data:`FITTED_KEYS`, current offset in µA,
    position zero in µm, pressure zero in kPa); ``free`` selects the entries a stage fits (the
    others stay at ``theta``), ``channels`` the outputs it compares."""

    def __init__(self, rec: Record, start: PlantParams) -> None:
        self.rec, self.start = rec, start
        self.y = _measured(rec)
        self.mask = np.isfinite(self.y) & np.isfinite(rec.applied_a)[:, None]
        self.sigma = np.array([_rms(self.y[self.mask[:, i], i]) for i in range(3)])
        self.theta = np.zeros(len(FITTED_KEYS) + N_OFFSETS)
        self.free: list[int] = list(range(self.theta.size))
        self.channels: list[int] = [0, 1, 2]

    def full(self, free_theta: Array) -> Array:
        th = self.theta.copy()
        th[self.free] = free_theta
        return th

    def plant(self, theta: Array) -> PlantParams:
        over = {k: getattr(self.start, k) * math.exp(t) for k, t in zip(FITTED_KEYS, theta, strict=False)}
        return replace(self.start, **over)

    def outputs(self, theta: Array) -> Array:
        n = len(FITTED_KEYS)
        out = simulate(self.plant(theta), self.rec.applied_a, self.rec.ts_s, theta[n] * 1e-6)
        out[:, 0] += theta[n + 1] * 1e-6
        out[:, 2] += theta[n + 2] * 1e3
        return out

    def residuals(self, free_theta: Array) -> Array:
        ch = self.channels
        r = (self.y[:, ch] - self.outputs(self.full(free_theta))[:, ch]) / self.sigma[ch]
        return r[self.mask[:, ch]]


def _rms(v: Array) -> float:
    return float(np.sqrt(np.mean(v**2))) if v.size else 1.0


def fit(rec: Record, start: Params) -> FitResult:
    """Fit :data:`FITTED_KEYS` (starting from ``start.plant``) and the offsets to ``rec``: the
    valve alone on the spool LVDT first (its keys and the null offset), then everything on all
    three channels, twice (the second time each channel weighted by its residual level)."""
    prob = _Problem(rec, start.plant)
    n = len(FITTED_KEYS)
    evals = _solve(prob, [0, 1, 2, n], [1])
    for _ in range(2):
        evals += _solve(prob, list(range(n + N_OFFSETS)), [0, 1, 2])
        resid = prob.y - prob.outputs(prob.theta)
        prob.sigma = np.array([_rms(resid[prob.mask[:, i], i]) for i in range(3)])
    r = prob.residuals(prob.theta)
    jac = _jacobian(prob, prob.theta)
    dof = max(r.size - prob.theta.size, 1)
    cov = np.linalg.pinv(jac.T @ jac) * float(r @ r) / dof
    return _result(prob, start, prob.theta, cov, evals)


def _solve(prob: _Problem, free: list[int], channels: list[int]) -> int:
    """One least-squares stage over the entries ``free`` of θ; returns the evaluations used."""
    from scipy.optimize import least_squares

    prob.free, prob.channels = free, channels
    n = len(FITTED_KEYS)
    lo = np.array([-LOG_BOUND if i < n else -np.inf for i in free])
    hi = np.array([LOG_BOUND if i < n else np.inf for i in free])
    sol = least_squares(
        prob.residuals, prob.theta[free], bounds=(lo, hi), x_scale="jac", xtol=1e-12, ftol=1e-12
    )
    prob.theta = prob.full(sol.x)
    return int(sol.nfev)


def _jacobian(prob: _Problem, theta: Array) -> Array:
    """Central-difference Jacobian of the weighted residuals at the solution."""
    cols = []
    for i in range(theta.size):
        h = 1e-6 * max(1.0, abs(theta[i]))
        up, dn = theta.copy(), theta.copy()
        up[i] += h
        dn[i] -= h
        cols.append((prob.residuals(up) - prob.residuals(dn)) / (2.0 * h))
    return np.column_stack(cols)


def _log_estimate(name: str, value: float, grad: Array, cov: Array, unit: str) -> Estimate:
    """A quantity whose log is linear in θ with gradient ``grad``: relative 95 % half-width."""
    sd = math.sqrt(max(float(grad @ cov @ grad), 0.0))
    return Estimate(name, value, math.expm1(Z95 * sd), unit)


#: each derived quantity as ``const·Π key^power``: name → (const, {key: power}, unit)
DERIVED: dict[str, tuple[float, dict[str, float], str]] = {
    "omega_sv_rad_s": (1.0, {"valve_stiffness_1_s2": 0.5}, "rad/s"),
    "zeta_sv": (0.5, {"valve_damping_1_s": 1.0, "valve_stiffness_1_s2": -0.5}, ""),
    "valve_static_gain_m_per_a": (1.0, {"valve_gain_m_per_a_s2": 1.0, "valve_stiffness_1_s2": -1.0}, "m/A"),
    "omega_h_rad_s": (1.0, {"hydraulic_stiffness_1_s2": 0.5}, "rad/s"),
    "zeta_h": (0.5, {"cylinder_damping_1_s": 1.0, "hydraulic_stiffness_1_s2": -0.5}, ""),
    "velocity_gain_1_s": (1.0, {"flow_gain_1_s3": 1.0, "hydraulic_stiffness_1_s2": -1.0}, "1/s"),
}
#: the unit of each fitted key
UNITS = {
    "valve_gain_m_per_a_s2": "m/(A·s²)",
    "valve_stiffness_1_s2": "1/s²",
    "valve_damping_1_s": "1/s",
    "flow_gain_1_s3": "1/s³",
    "hydraulic_stiffness_1_s2": "1/s²",
    "cylinder_damping_1_s": "1/s",
}


def _result(prob: _Problem, start: Params, theta: Array, cov: Array, evals: int) -> FitResult:
    n = len(FITTED_KEYS)
    plant = prob.plant(theta)
    e = np.eye(n + N_OFFSETS)
    keys = tuple(_log_estimate(k, getattr(plant, k), e[i], cov, UNITS[k]) for i, k in enumerate(FITTED_KEYS))
    derived = []
    for name, (const, powers, unit) in DERIVED.items():
        value = const * math.prod(getattr(plant, k) ** a for k, a in powers.items())
        grad = sum((a * e[FITTED_KEYS.index(k)] for k, a in powers.items()), np.zeros(n + N_OFFSETS))
        derived.append(_log_estimate(name, value, grad, cov, unit))
    k_sv = plant.valve_static_gain_m_per_a
    i0, sd_i0 = theta[n] * 1e-6, math.sqrt(max(cov[n, n], 0.0)) * 1e-6
    y0, sd_y0 = theta[n + 1] * 1e-6, math.sqrt(max(cov[n + 1, n + 1], 0.0)) * 1e-6
    null = Estimate("spool_null_offset_m", i0 * k_sv, Z95 * sd_i0 * k_sv, "m (± absolute)")
    zero = Estimate("position_zero_m", y0, Z95 * sd_y0, "m (± absolute)")
    resid = prob.y - prob.outputs(theta)
    rms = {c: _rms(resid[prob.mask[:, i], i]) for i, c in enumerate(CHANNELS)}
    fitted = check_closed_loop_stable(replace(start, plant=plant))
    return FitResult(fitted, keys, tuple(derived), null, zero, rms, evals)
