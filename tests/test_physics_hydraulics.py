"""The nonlinear valve-controlled cylinder (physics/hydraulics.py): its linearisation is the
lumped eq 39 plant, and its nonlinear features do what the physics says."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ehpss_hil.physics.hydraulics import NonlinearPlant, derive
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import LinearPlant, make_plant
from ehpss_hil.physics.plantspec import PlantSpec
from ehpss_hil.report.metrics import compute_metrics
from ehpss_hil.scenario import Reference, Scenario
from ehpss_hil.sim.lockstep import run_scenario

PARAMS = load_params()
BASE = PARAMS.plant
TS = 1e-3
#: the paper's proportional path K_f·K_a·K_p (A per metre of position error)
P_GAIN_A_PER_M = PARAMS.controller.k_f * PARAMS.controller.k_a * PARAMS.controller.k_p


def _nonlinear(ts_s: float = TS, **keys: float) -> NonlinearPlant:
    plant = make_plant(PlantSpec(model="nonlinear", **keys), BASE, ts_s)  # type: ignore[arg-type]
    assert isinstance(plant, NonlinearPlant)
    return plant


def _drive(plant: LinearPlant | NonlinearPlant, current: list[float]) -> tuple[np.ndarray, np.ndarray]:
    xs, pl = [], []
    for i in current:
        plant.step(i)
        xs.append(plant.position_m)
        pl.append(plant.load_pressure_pa)
    return np.array(xs), np.array(pl)


def test_mapping_reproduces_the_lumped_coefficients() -> None:
    """ω_h² = 4β_e·A²/(V_t·m), K_q·ω_h²/A = flow_gain, κ·K_ce = cylinder_damping (B_v = 0)."""
    hp = derive(BASE, PlantSpec(model="nonlinear"))
    a, m = BASE.piston_area_m2, BASE.load_mass_kg
    v_t = 2.0 * a * hp.chamber_length_m
    kappa = 4.0 * hp.bulk_modulus_pa / v_t
    assert hp.natural_frequency_rad_s() ** 2 == pytest.approx(BASE.hydraulic_stiffness_1_s2, rel=1e-12)
    k_q = hp.valve_coefficient * math.sqrt((hp.supply_pressure_pa - hp.return_pressure_pa) / 2.0)
    assert kappa * k_q * a / m == pytest.approx(BASE.flow_gain_1_s3, rel=1e-12)
    k_ce = hp.land_leak_m3_s_pa + hp.internal_leak_m3_s_pa
    assert kappa * k_ce == pytest.approx(BASE.cylinder_damping_1_s, rel=1e-12)
    # ω_h grows towards an end stop (the smaller chamber stiffens)
    assert hp.natural_frequency_rad_s(0.9 * hp.piston_stroke_m) > 1.3 * hp.natural_frequency_rad_s()


@pytest.mark.parametrize(
    "keys,ts_s",
    [
        ({}, TS),
        ({"viscous_friction_n_s_m": 2.0e4}, TS),
        ({"return_pressure_pa": 5e5}, TS),
        ({}, 5e-4),
        ({}, 2e-3),
    ],
)
def test_small_signals_follow_the_linear_plant(keys: dict[str, float], ts_s: float) -> None:
    """Open loop, a small spool sine plus a pulse: position within 1 %, load pressure within
    10 % (RMS of the difference over the RMS of the signal) of the linear plant. (With viscous
    friction the lumped model's P_L = m·ẍ/A leaves out B_v·ẋ/A; at 2 ms a sample sees only the
    tail of each current step's transient, P_L ten times smaller than within it, and relative
    to that tail the sub-steps' warping is 29 %: position only.)"""
    t = np.arange(round(2.0 / ts_s)) * ts_s
    # ±0.33 mm of spool and a 0.17 mm pulse (full stroke is 10 mm at 0.61 mA)
    current = (2e-5 * np.sin(2 * np.pi * 20 * t) + np.where((t > 0.1) & (t < 0.3), 1e-5, 0.0)).tolist()
    x_l, p_l = _drive(LinearPlant(BASE, ts_s), current)
    x_n, p_n = _drive(_nonlinear(ts_s, **keys), current)
    rms = lambda v: float(np.sqrt(np.mean(v**2)))  # noqa: E731
    assert rms(x_n - x_l) < 0.01 * rms(x_l)
    if not keys.get("viscous_friction_n_s_m") and ts_s <= TS:
        assert rms(p_n - p_l) < 0.10 * rms(p_l)


def test_nrc_rms_on_a_small_sine_matches_the_linear_plant() -> None:
    sc = Scenario(
        name="s", duration_s=2.0, reference=Reference(kind="sine", amplitude_m=1e-4, omega_rad_s=5.0)
    )
    lin = compute_metrics(run_scenario(sc, "nrc", PARAMS)).rms_error_m
    nl = compute_metrics(
        run_scenario(replace(sc, plant=PlantSpec(model="nonlinear")), "nrc", PARAMS)
    ).rms_error_m
    assert lin > 0.0
    assert nl == pytest.approx(lin, rel=0.10)


def test_pressures_stay_within_return_and_supply_on_large_motions() -> None:
    sc = Scenario(
        name="s",
        duration_s=2.0,
        reference=Reference(kind="sine", amplitude_m=5e-3, omega_rad_s=10.0),
        plant=PlantSpec(model="nonlinear", area_ratio=0.6, return_pressure_pa=3e5),
    )
    from ehpss_hil.emulation import PlantEmulation

    emu = PlantEmulation(PARAMS, sc)
    plant = emu.plant
    assert isinstance(plant, NonlinearPlant)
    lo, hi = 3e5, plant.hp.supply_pressure_pa
    x_d = sc.reference_samples()
    for k in range(sc.n_samples):  # a P controller on the true position (the spool saturates)
        emu.advance(P_GAIN_A_PER_M * (x_d[k] - plant.position_m))
        pa, pb = plant.chamber_pressures_pa
        assert lo - 1e3 <= pa <= hi + 1e3 and lo - 1e3 <= pb <= hi + 1e3, (k, pa, pb)
    assert np.isfinite(plant.position_m)


def test_end_stops_hold_and_pressure_builds_to_supply() -> None:
    plant = _nonlinear(piston_stroke_m=0.005)
    for _ in range(3000):  # full spool: ≈ 33 mm/s, the stop reached after ≈ 0.15 s
        plant.step(0.1)
    assert plant.position_m == 0.005
    assert plant.velocity_m_s == 0.0
    pa, pb = plant.chamber_pressures_pa
    hp = plant.hp
    # stalled: the orifices feed only the leakage, most of the supply pressure is across the piston
    assert hp.return_pressure_pa < pb < pa < hp.supply_pressure_pa
    assert pa - pb > 0.5 * hp.supply_pressure_pa
    for _ in range(3000):
        plant.step(-0.1)
    assert plant.position_m == -0.005


def _steady_speed(plant: NonlinearPlant, current: float, samples: int = 300) -> float:
    x0 = 0.0
    for k in range(samples):
        plant.step(current)
        if k == samples // 2:
            x0 = plant.position_m
    return (plant.position_m - x0) / ((samples - samples // 2 - 1) * TS)


def test_area_ratio_makes_extension_faster_than_retraction() -> None:
    """No load, little leakage, a symmetric critical-centre valve: v_ext/v_ret = 1/√α, and
    v_ext = K_v·x·√P_S/(A_A·√(1 + α³)) (steady orifice flows with the force balance)."""
    alpha = 0.6
    keys = {"area_ratio": alpha, "cylinder_damping_1_s": 5.0, "piston_stroke_m": 0.2}
    ext = _nonlinear(**keys)
    v_ext = _steady_speed(ext, 0.05)
    ret = _nonlinear(**keys)
    v_ret = -_steady_speed(ret, -0.05)
    assert v_ext / v_ret == pytest.approx(1.0 / math.sqrt(alpha), rel=0.02)
    hp = ext.hp
    expected = hp.valve_coefficient * ext.spool_actual_m * math.sqrt(hp.supply_pressure_pa)
    expected /= hp.area_a_m2 * math.sqrt(1.0 + alpha**3)
    assert v_ext == pytest.approx(expected, rel=0.02)


def test_overlap_is_a_dead_band() -> None:
    """A spool inside the overlap opens no orifice: the piston stays; beyond it, it moves."""
    small = 0.5e-3 / BASE.valve_static_gain_m_per_a  # current for a 0.5 mm spool
    lapped = _nonlinear(spool_overlap_m=1e-3)
    critical = _nonlinear()
    for _ in range(500):
        lapped.step(small)
        critical.step(small)
    assert abs(lapped.position_m) < 1e-9
    assert critical.position_m > 1e-4
    for _ in range(500):
        lapped.step(3.0 * small)  # 1.5 mm spool: 0.5 mm open
    assert lapped.position_m > 1e-4


def test_rest_is_an_equilibrium_and_a_load_is_held_by_pressure() -> None:
    plant = _nonlinear()
    for _ in range(200):
        plant.step(0.0)
    assert plant.position_m == 0.0
    assert plant.chamber_pressures_pa == (plant.hp.rest_pressure_pa, plant.hp.rest_pressure_pa)
    f_ext = 500.0
    loaded = _nonlinear(external_force_n=f_ext, coulomb_friction_n=50.0)
    for _ in range(4000):  # a P loop on the true position holds x = 0 against the load
        loaded.step(-P_GAIN_A_PER_M * loaded.position_m)
    assert abs(loaded.position_m) < 1e-4
    # at rest, the net hydraulic force carries the load (Coulomb friction within ±50 N)
    assert loaded.load_pressure_pa * BASE.piston_area_m2 == pytest.approx(f_ext, abs=60.0)


def test_faults_act_on_the_nonlinear_plant() -> None:
    """k_Q scales the orifice coefficient (the piston speed), k_LOE the actual spool, and the
    current limit the applied current."""
    from ehpss_hil.physics.faults import FaultState

    healthy = _nonlinear(cylinder_damping_1_s=5.0)
    v1 = _steady_speed(healthy, 2e-4)  # a 3.3 mm spool
    slow = _nonlinear(cylinder_damping_1_s=5.0)
    slow.set_faults(FaultState(k_q=0.5))
    assert _steady_speed(slow, 2e-4) == pytest.approx(0.5 * v1, rel=0.03)
    loe = _nonlinear()
    loe.set_faults(FaultState(k_loe=0.5, current_limit_a=0.01))
    assert loe.step(0.5) == 0.01
    for _ in range(50):
        loe.step(1e-4)
    assert loe.spool_actual_m == pytest.approx(0.5 * loe.spool_commanded_m)
    assert loe.spool_commanded_m == pytest.approx(1e-4 * BASE.valve_static_gain_m_per_a, rel=1e-3)
    for _ in range(50):
        loe.step(3e-3)  # 49 mm commanded: the actual spool stops at the 10 mm stroke
    assert loe.spool_actual_m == BASE.spool_stroke_m


@pytest.mark.parametrize("model", ["linear", "nonlinear"])
def test_outputs_are_the_four_sensor_properties_in_one_call(model: str) -> None:
    """``Plant.outputs()`` (what the emulation reads each sample) gives exactly the properties
    position, actual spool, load pressure and current echo, in that order, also under a k_LOE
    fault and a current limit (values that differ from one another, each non-zero)."""
    from ehpss_hil.physics.faults import FaultState

    plant = make_plant(PlantSpec(model=model), BASE, TS)  # type: ignore[arg-type]
    plant.set_faults(FaultState(k_loe=0.7, current_limit_a=0.004))
    for k in range(200):
        plant.step(0.01 * math.sin(0.05 * k))
        out = plant.outputs()
        assert out == (plant.position_m, plant.spool_actual_m, plant.load_pressure_pa, plant.coil_current_a)
    assert len(set(out)) == 4 and all(v != 0.0 for v in out)
    assert abs(out[3]) <= 0.004
