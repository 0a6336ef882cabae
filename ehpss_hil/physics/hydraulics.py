"""The nonlinear valve-controlled single-rod cylinder (docs/physics.md "Nonlinear plant";
Merritt, *Hydraulic Control Systems*, ch. 5–6; Jelali & Kroll, *Hydraulic Servo-systems*, ch. 3).

Servo valve: the 2nd-order spool of eq 7 (exact ZOH per sub-step) with its stroke and k_LOE on
the actual spool. A 4-way spool with overlap u: opening x_e = sign(x_s)·max(|x_s| − u, 0);
turbulent orifice flow Q = K_v·x_e·q(Δp) on each land, K_v = C_d·w·√(2/ρ) (k_Q scales it), and a
laminar leak C_l on each land (it keeps the pressures defined at null). Chambers
V_A = A_A·(L_0 + x), V_B = A_B·(L_0 − x), oil bulk modulus β_e, internal leakage C_i:
``Ṗ_A = β_e/V_A·(Q_A − A_A·ẋ − C_i·(P_A − P_B))``, ``Ṗ_B = β_e/V_B·(Q_B + A_B·ẋ + C_i·(P_A − P_B))``.
Motion: ``m·ẍ = A_A·P_A − A_B·P_B − B_v·ẋ − F_c·tanh(ẋ/v_s) − k·x − F_ext`` with inelastic end
stops at ±piston_stroke.

Defaults derive from params.yaml's lumped keys so that with area ratio 1, no Coulomb friction,
overlap, spring or load, a centred piston and small signals the plant linearises to the lumped
model: ``flow_gain = κ·K_q·A/m``, ``cylinder_damping = κ·K_ce + B_v/m``,
``hydraulic_stiffness = κ·(A² + K_ce·B_v)/m`` with ``κ = 4β_e/V_t``, ``V_t = 2·A·L_0``,
``K_q = K_v·√((P_S − P_T)/2)`` and ``K_ce = C_l + C_i`` (:func:`derive`).

Integration: per sample, :data:`SUBSTEP_MAX_S`-bounded sub-steps of the linearly implicit
trapezoidal rule (one Newton step of the trapezoidal rule with the analytic Jacobian, solved by
elimination on Python floats): A-stable, second order, exact for a linear system up to the
rule's frequency warping, so the stiff hydraulic mode (ω_h ≈ 5600 rad/s) and a stalled orifice
cannot blow up as explicit methods do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import ConfigError
from .discretize import zoh
from .faults import FaultState
from .fmumap import ACTUATOR_FAULTS
from .model import valve_matrices
from .params import PlantParams
from .plantspec import RETURN_PRESSURE_PA, SUPPLY_PRESSURE_PA, PlantSpec

#: piston end stops at ± this from the centre (m) when the scenario gives none
PISTON_STROKE_M = 0.05
#: oil beyond an end stop as a length of the bore (m) when the scenario gives none
DEAD_LENGTH_M = 0.01
#: velocity scale of the Coulomb friction's tanh (m/s) when the scenario gives none
FRICTION_VELOCITY_M_S = 1e-3
#: share of the leakage coefficient K_ce that leaks across the valve's lands (the rest across
#: the piston, C_i): only the sum enters the linearisation
LAND_LEAK_SHARE = 0.5
#: the orifice law turns laminar below this fraction of P_S − P_T (keeps √Δp differentiable)
ORIFICE_LAMINAR_FRACTION = 0.01
#: longest integration sub-step (s): 8 per 1 ms sample, ω_h·h = 0.7 at the centre, where the
#: trapezoidal rule puts the hydraulic mode 3.8 % low ((2/h)·atan(ω_h·h/2)); the error is
#: O(h²): small-signal load pressure within 7.5 % RMS of the exact lumped plant, position 0.03 %
SUBSTEP_MAX_S = 1.25e-4


@dataclass(frozen=True)
class HydraulicParams:
    """The physical parameters of the nonlinear plant (SI), derived by :func:`derive`."""

    area_a_m2: float
    area_b_m2: float
    mass_kg: float
    bulk_modulus_pa: float
    chamber_length_m: float
    valve_coefficient: float  # K_v = C_d·w·√(2/ρ) (m²/(s·√Pa))
    land_leak_m3_s_pa: float  # C_l per land
    internal_leak_m3_s_pa: float  # C_i across the piston
    viscous_friction_n_s_m: float
    coulomb_friction_n: float
    friction_velocity_m_s: float
    spring_n_m: float
    external_force_n: float
    supply_pressure_pa: float
    return_pressure_pa: float
    piston_stroke_m: float
    spool_overlap_m: float
    spool_stroke_m: float

    @property
    def rest_pressure_pa(self) -> float:
        """Both chambers at rest with the valve centred: (P_S + P_T)/2 (Pa)."""
        return 0.5 * (self.supply_pressure_pa + self.return_pressure_pa)

    def natural_frequency_rad_s(self, x_m: float = 0.0) -> float:
        """ω_h at piston position x (m): √(β_e·(A_A²/V_A + A_B²/V_B)/m) (rad/s)."""
        va = self.area_a_m2 * (self.chamber_length_m + x_m)
        vb = self.area_b_m2 * (self.chamber_length_m - x_m)
        k_h = self.bulk_modulus_pa * (self.area_a_m2**2 / va + self.area_b_m2**2 / vb)
        return math.sqrt(k_h / self.mass_kg)


def _or(value: float | None, default: float) -> float:
    return default if value is None else value


def derive(plant: PlantParams, spec: PlantSpec) -> HydraulicParams:
    """The nonlinear plant's parameters from the lumped ``plant`` (already with the scenario's
    overrides) and the scenario's nonlinear keys (module docstring: the mapping)."""
    a, m = plant.piston_area_m2, plant.load_mass_kg
    c, k, f = plant.cylinder_damping_1_s, plant.hydraulic_stiffness_1_s2, plant.flow_gain_1_s3
    b_v = _or(spec.viscous_friction_n_s_m, 0.0)
    damping_left = c - b_v / m  # κ·K_ce
    if damping_left <= 0.0:
        raise ConfigError(
            "", "plant.viscous_friction_n_s_m", f"B_v/m must stay below cylinder_damping ({c:g} 1/s)"
        )
    kappa = (k * m - damping_left * b_v) / a**2  # 4β_e/V_t (Pa/m³)
    k_ce = damping_left / kappa
    k_q = f * m / (kappa * a)
    p_s = _or(spec.supply_pressure_pa, SUPPLY_PRESSURE_PA)
    p_t = _or(spec.return_pressure_pa, RETURN_PRESSURE_PA)
    stroke = _or(spec.piston_stroke_m, PISTON_STROKE_M)
    length = stroke + _or(spec.dead_length_m, DEAD_LENGTH_M)
    return HydraulicParams(
        area_a_m2=a,
        area_b_m2=a * _or(spec.area_ratio, 1.0),
        mass_kg=m,
        bulk_modulus_pa=kappa * 2.0 * a * length / 4.0,
        chamber_length_m=length,
        valve_coefficient=k_q * math.sqrt(2.0 / (p_s - p_t)),
        land_leak_m3_s_pa=LAND_LEAK_SHARE * k_ce,
        internal_leak_m3_s_pa=(1.0 - LAND_LEAK_SHARE) * k_ce,
        viscous_friction_n_s_m=b_v,
        coulomb_friction_n=_or(spec.coulomb_friction_n, 0.0),
        friction_velocity_m_s=_or(spec.friction_velocity_m_s, FRICTION_VELOCITY_M_S),
        spring_n_m=_or(spec.spring_n_m, 0.0),
        external_force_n=_or(spec.external_force_n, 0.0),
        supply_pressure_pa=p_s,
        return_pressure_pa=p_t,
        piston_stroke_m=stroke,
        spool_overlap_m=_or(spec.spool_overlap_m, 0.0),
        spool_stroke_m=plant.spool_stroke_m,
    )


class NonlinearPlant:
    """The valve-controlled single-rod cylinder behind the :class:`~.plant.Plant` protocol.

    State: valve ``[ẋ_v, x_v]`` (commanded spool, m/s and m), chamber pressures ``P_A, P_B`` (Pa),
    piston position and velocity ``x, ẋ`` (m, m/s). Faults: k_LOE scales the actual spool (which
    stops at the spool stroke), k_Q the orifice coefficient K_v, ``current_limit_a`` the current.
    """

    __slots__ = (
        "_consts",
        "_h",
        "_kv",
        "_p_lam",
        "_pa",
        "_pb",
        "_spool_stop_m",
        "_u",
        "_v",
        "_valve",
        "_vv",
        "_x",
        "_xv",
        "faults",
        "hp",
        "modelled_faults",
        "substeps",
        "ts_s",
    )

    def __init__(self, hp: HydraulicParams, plant: PlantParams, ts_s: float) -> None:
        self.hp = hp
        self.ts_s = ts_s
        self.substeps = max(1, math.ceil(ts_s / SUBSTEP_MAX_S - 1e-9))
        h = ts_s / self.substeps
        self._h = h
        ad, bd = zoh(*valve_matrices(plant), h)
        self._valve = (
            (float(ad[0, 0]), float(ad[0, 1]), float(bd[0, 0])),
            (float(ad[1, 0]), float(ad[1, 1]), float(bd[1, 0])),
        )
        self._p_lam = ORIFICE_LAMINAR_FRACTION * (hp.supply_pressure_pa - hp.return_pressure_pa)
        self._consts = _step_constants(hp, h)
        self.modelled_faults = frozenset(ACTUATOR_FAULTS)
        self.faults = FaultState()
        self.reset()

    def reset(self) -> None:
        """Valve centred, piston centred at rest, both chambers at the rest pressure (with
        ``area_ratio`` < 1 that is no equilibrium: the net force (1 − α)·A_A·P_0 moves the piston
        until the loop opens the valve, as a real single-rod cylinder on a centred valve creeps)."""
        p0 = self.hp.rest_pressure_pa
        self._vv, self._xv = 0.0, 0.0
        self._pa, self._pb, self._x, self._v = p0, p0, 0.0, 0.0
        self._u = 0.0
        self.set_faults(FaultState())

    def set_faults(self, faults: FaultState) -> None:
        """Apply new fault values from the next sample on."""
        self.faults = faults
        self._kv = self.hp.valve_coefficient * faults.k_q
        self._spool_stop_m = self.hp.spool_stroke_m / faults.k_loe  # where x_v stops (m)

    # ---- sensors ----------------------------------------------------------------------------
    def outputs(self) -> tuple[float, float, float, float]:
        """``(x, k_loe·x_v, P_L, applied current)`` (m, m, Pa, A): the properties below in one
        call (the emulation reads them every sample), expression for expression."""
        hp = self.hp
        p_l = self._pa - hp.area_b_m2 / hp.area_a_m2 * self._pb
        return self._x, self.faults.k_loe * self._xv, p_l, self._u

    @property
    def position_m(self) -> float:
        """True piston position x (m)."""
        return self._x

    @property
    def velocity_m_s(self) -> float:
        """Piston velocity ẋ (m/s)."""
        return self._v

    @property
    def spool_actual_m(self) -> float:
        """Actual spool k_LOE·x_v (m), within the stroke: what the spool LVDT measures."""
        return self.faults.k_loe * self._xv

    @property
    def spool_commanded_m(self) -> float:
        """Spool displacement the valve dynamics produce from the current, x_v (m)."""
        return self._xv

    @property
    def coil_current_a(self) -> float:
        """The current applied over the last sample (A): the amplifier's echo."""
        return self._u

    @property
    def chamber_pressures_pa(self) -> tuple[float, float]:
        """Cap-side and rod-side chamber pressures ``(P_A, P_B)`` (Pa)."""
        return self._pa, self._pb

    @property
    def load_pressure_pa(self) -> float:
        """Load pressure P_L = P_A − (A_B/A_A)·P_B (Pa): the net hydraulic force over A_A."""
        hp = self.hp
        return self._pa - hp.area_b_m2 / hp.area_a_m2 * self._pb

    # ---- dynamics ---------------------------------------------------------------------------
    def step(self, current_a: float) -> float:
        """Advance one sample with ``current_a`` held (sub-steps, module docstring); returns the
        applied (limited) current (A)."""
        lim = self.faults.current_limit_a
        u = -lim if current_a < -lim else lim if current_a > lim else current_a  # min(max(…)) inline
        self._u = u
        self._substeps(u)
        return u

    def _substeps(self, u: float) -> None:
        """The sample's sub-steps, each: the valve (exact ZOH, the actual spool stopped
        inelastically at the stroke), then with the sub-step's mean actual spool (m, held over
        it) a linearly implicit trapezoidal step of ``(P_A, P_B, x, ẋ)``, then the end stops.
        Each solves ``(I − h/2·J)·Δ = h·f`` with the analytic Jacobian J: Δx = h·ẋ + h/2·Δẋ
        eliminated, then (ΔP_A, ΔP_B) in terms of Δẋ (2×2), then Δẋ (scalar). One loop over
        locals only: the simulator's hot path (the valve does not depend on the cylinder, so
        stepping both in one loop is the same arithmetic as the valve's path first)."""
        (v0, v1, vb), (x0, x1, xb) = self._valve
        stop = self._spool_stop_m
        below = -stop
        half_loe = 0.5 * self.faults.k_loe  # 0.5·k_LOE·(…) evaluates as (0.5·k_LOE)·(…): hoisted
        vv, xv = self._vv, self._xv
        kv, lam = self._kv, self._p_lam
        (h, hba, hbb, length, ps, pt, lap, cl2, leak0, aa, ab, ci, bv, fc, vs, ks, fext, stroke, th) = (
            self._consts[:19]
        )
        cv0, cvf, ca, cb, hm, hks = self._consts[19:]
        den_viscous = cv0 + cvf * bv  # the Δẋ coefficient's friction part without Coulomb friction
        pa, pb, x, v = self._pa, self._pb, self._x, self._v
        sqrt = math.sqrt
        for _ in range(self.substeps):
            xs0 = xv  # the valve over this sub-step, and its mean actual spool xs
            vv, xv = v0 * vv + v1 * xv + vb * u, x0 * vv + x1 * xv + xb * u
            if xv > stop or xv < below:
                xv, vv = (stop if xv > 0.0 else below), 0.0
            xs = half_loe * (xs0 + xv)
            hea = hba / (length + x)  # h·β_e/V_A
            heb = hbb / (length - x)  # h·β_e/V_B
            tea, teb = 0.5 * hea, 0.5 * heb
            qa = leak0 - cl2 * pa
            qb = leak0 - cl2 * pb
            ga = gb = cl2
            if xs > lap:  # P → A, B → T (√ inline when turbulent: the hot path)
                kx = kv * (xs - lap)
                dp = ps - pa
                if dp > lam:
                    d = sqrt(dp)
                    sl = 0.5 / d
                else:
                    d, sl = _orifice(dp, lam)
                qa += kx * d
                ga += kx * sl
                dp = pb - pt
                if dp > lam:
                    d = sqrt(dp)
                    sl = 0.5 / d
                else:
                    d, sl = _orifice(dp, lam)
                qb -= kx * d
                gb += kx * sl
            elif xs < -lap:  # A → T, P → B
                kx = kv * (-lap - xs)
                dp = pa - pt
                if dp > lam:
                    d = sqrt(dp)
                    sl = 0.5 / d
                else:
                    d, sl = _orifice(dp, lam)
                qa -= kx * d
                ga += kx * sl
                dp = ps - pb
                if dp > lam:
                    d = sqrt(dp)
                    sl = 0.5 / d
                else:
                    d, sl = _orifice(dp, lam)
                qb += kx * d
                gb += kx * sl
            qi = ci * (pa - pb)
            if fc > 0.0:
                tv = math.tanh(v / vs)
                friction = bv * v + fc * tv
                den0 = cv0 + cvf * (bv + fc * (1.0 - tv * tv) / vs)  # with dfriction/dẋ
            else:
                friction, den0 = bv * v, den_viscous
            r1, r2 = hea * (qa - aa * v - qi), heb * (qb + ab * v + qi)
            m11, m12 = 1.0 + tea * (ga + ci), -tea * ci
            m21, m22 = -teb * ci, 1.0 + teb * (gb + ci)
            s1, s2 = -tea * aa, teb * ab
            inv = 1.0 / (m11 * m22 - m12 * m21)
            pa0, qa_v = (m22 * r1 - m12 * r2) * inv, (m22 * s1 - m12 * s2) * inv
            pb0, qb_v = (m11 * r2 - m21 * r1) * inv, (m11 * s2 - m21 * s1) * inv
            force = aa * pa - ab * pb - friction - ks * x - fext  # m·ẍ (N)
            dv = (hm * force - hks * v - ca * pa0 - cb * pb0) / (den0 + ca * qa_v + cb * qb_v)
            pa += pa0 + qa_v * dv
            pb += pb0 + qb_v * dv
            x += h * v + th * dv
            v += dv
            if x > stroke:
                x, v = stroke, min(v, 0.0)
            elif x < -stroke:
                x, v = -stroke, max(v, 0.0)
        self._vv, self._xv = vv, xv
        self._pa, self._pb, self._x, self._v = pa, pb, x, v


def _step_constants(hp: HydraulicParams, h: float) -> tuple[float, ...]:
    """The per-sub-step constants of :meth:`NonlinearPlant._substeps` for sub-step ``h`` (s),
    computed once with the same operations (and so the same values) as written out per step:
    ``(h, h·β_e/A_A, h·β_e/A_B, L_0, P_S, P_T, overlap, 2·C_l, land leak at zero pressure, A_A,
    A_B, C_i, B_v, F_c, v_s, k, F_ext, piston stroke, h/2)`` and the v row's coefficients
    ``(1 + (h/2)²·k/m, (h/2)/m, −(h/2)·A_A/m, (h/2)·A_B/m, h/m, (h/2)·h·k/m)``."""
    aa, ab, m, ks = hp.area_a_m2, hp.area_b_m2, hp.mass_kg, hp.spring_n_m
    ps, pt, cl2 = hp.supply_pressure_pa, hp.return_pressure_pa, 2.0 * hp.land_leak_m3_s_pa
    th = 0.5 * h
    leak0 = 0.5 * cl2 * (ps + pt)  # land leaks into a chamber at zero pressure (m³/s)
    return (
        h,
        h * (hp.bulk_modulus_pa / aa),
        h * (hp.bulk_modulus_pa / ab),
        hp.chamber_length_m,
        ps,
        pt,
        hp.spool_overlap_m,
        cl2,
        leak0,
        aa,
        ab,
        hp.internal_leak_m3_s_pa,
        hp.viscous_friction_n_s_m,
        hp.coulomb_friction_n,
        hp.friction_velocity_m_s,
        ks,
        hp.external_force_n,
        hp.piston_stroke_m,
        th,
        1.0 + th * th * ks / m,
        th / m,
        -th * aa / m,
        th * ab / m,
        h / m,
        th * h * ks / m,
    )


def _orifice(dp: float, lam: float) -> tuple[float, float]:
    """``(q, dq/dΔp)`` of the orifice law q(Δp) = sign(Δp)·√|Δp| (√Pa), laminar (linear,
    matching value and continuous) below ``lam`` Pa."""
    if dp >= lam:
        r = math.sqrt(dp)
        return r, 0.5 / r
    if dp <= -lam:
        r = math.sqrt(-dp)
        return -r, 0.5 / r
    k = 1.0 / math.sqrt(lam)
    return dp * k, k
