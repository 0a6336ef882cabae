"""Physics: eq 39 matrices, exact ZOH, reference model, fault-induced eigenvalue motion."""

from __future__ import annotations

from collections.abc import Hashable
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import cont2discrete

from ehpss_hil.errors import ConfigError
from ehpss_hil.physics import FaultState, load_params
from ehpss_hil.physics.discretize import Matrix, ZohCache, zoh
from ehpss_hil.physics.load import check_closed_loop_stable
from ehpss_hil.physics.model import closed_loop_matrices, plant_matrices
from ehpss_hil.physics.plant import PlantStepper
from ehpss_hil.physics.reference import ReferenceModel

PARAMS = load_params()


def eq39_printed(k_loe: float, k_dft: float) -> tuple[np.ndarray, np.ndarray]:
    """The paper's eq 39 numbers, with the fault entries of docs/design.md §6 (4 significant digits)."""
    a = np.zeros((6, 6))
    a[0, :] = [-2576, -3.136e7, 0, 0, 1.031e8 * k_loe, 0]
    a[1, 0] = 1
    a[2, 1] = 1
    a[3, :] = [0, 0, -4.263e8 * k_dft, -3402, -5.905e6, 1.677e7]
    a[4, 3] = 1
    a[5, 2] = -25.422 * k_dft
    b = np.array([0, 0, 0, 4.263e8, 0, 25.42])
    return a, b


@pytest.mark.parametrize("k_loe,k_dft", [(1, 1), (0.5, 1), (1, 0.5), (0.2, 0.8)])
def test_closed_loop_equals_eq39_to_4_digits(k_loe: float, k_dft: float) -> None:
    a, b, c = closed_loop_matrices(PARAMS, k_loe=k_loe, k_dft=k_dft)
    a_ref, b_ref = eq39_printed(k_loe, k_dft)
    np.testing.assert_allclose(a, a_ref, rtol=5e-4, atol=0)
    np.testing.assert_allclose(b[:, 0], b_ref, rtol=5e-4, atol=0)
    np.testing.assert_array_equal(c, [[0, 0, 1, 0, 0, 0]])


@pytest.mark.parametrize("ts", [1e-3, 5e-4, 2e-4])
def test_zoh_matches_cont2discrete(ts: float) -> None:
    for k_loe, k_q in [(1.0, 1.0), (0.5, 1.0), (0.2, 0.7)]:
        a, b = plant_matrices(PARAMS.plant, k_loe, k_q)
        ad, bd = zoh(a, b, ts)
        ad_s, bd_s, *_ = cont2discrete((a, b, np.eye(5), np.zeros((5, 1))), ts, method="zoh")
        np.testing.assert_allclose(ad, ad_s, rtol=1e-12, atol=1e-12 * np.abs(ad_s).max())
        np.testing.assert_allclose(bd, bd_s, rtol=1e-12, atol=1e-12 * np.abs(bd_s).max())


def test_fault_free_loop_stable_with_unit_dc_gain() -> None:
    a, b, c = closed_loop_matrices(PARAMS)
    assert np.linalg.eigvals(a).real.max() < 0
    dc = (-c @ np.linalg.solve(a, b)).item()
    assert dc == pytest.approx(1.0, abs=1e-9)


def test_loe_slows_the_dominant_real_pole() -> None:
    """Losing effectiveness moves the slow real pole (−284 rad/s fault-free) toward the origin."""

    def slow_pole(k_loe: float) -> float:
        eig = np.linalg.eigvals(closed_loop_matrices(PARAMS, k_loe=k_loe)[0])
        real = eig[np.abs(eig.imag) < 1e-6].real
        return float(real[real < -10].max())  # the real pole other than the integrator's ≈ −1

    p1, p05, p02 = slow_pole(1.0), slow_pole(0.5), slow_pole(0.2)
    assert p1 == pytest.approx(-284.2, abs=0.5)
    assert p1 < p05 < p02 < 0
    assert p05 == pytest.approx(-128.0, abs=0.5) and p02 == pytest.approx(-47.97, abs=0.5)


def test_drift_changes_dc_gain_to_one_over_kdft() -> None:
    a, b, c = closed_loop_matrices(PARAMS, k_dft=0.5)
    assert (-c @ np.linalg.solve(a, b)).item() == pytest.approx(2.0, rel=1e-9)


def test_reference_model_follows_sine_with_small_lag() -> None:
    """y_m lags a 1 mm, 5 rad/s sine by ≈ 23 µs peak (the slow integrator pole); no overshoot."""
    ts = 1e-3
    t = np.arange(4000) * ts
    r = 1e-3 * np.sin(5 * t)
    ym = ReferenceModel(PARAMS, ts).simulate(r)
    assert 1e-5 < np.abs(ym - r)[1000:].max() < 3e-5
    assert np.abs(ym).max() == pytest.approx(1e-3, rel=0.05)


def test_plant_stepper_zoh_cache_and_saturation() -> None:
    p = PlantStepper(PARAMS, 1e-3)
    p.set_faults(FaultState(k_loe=0.5))
    p.set_faults(FaultState(k_loe=0.5, k_dft=0.3))  # k_dft does not change the dynamics
    assert len(p._zoh) == 2  # fault-free + (0.5, 1.0)
    p.set_faults(FaultState(current_limit_a=1e-3))
    assert p.step(0.5) == 1e-3
    assert p.state[4] > 0


def test_zoh_cache_evicts_beyond_capacity() -> None:
    def build(k: Hashable) -> tuple[Matrix, Matrix]:
        assert isinstance(k, float)  # the keys below are k_loe values
        return plant_matrices(PARAMS.plant, k, 1.0)

    cache = ZohCache(build, 1e-3, max_entries=2)
    for k in (1.0, 0.9, 0.8):
        cache.get(k)
    assert len(cache) == 2


def test_errata_checks() -> None:
    """Table 1 does not give eq 39's ω_h; C·B = 0 (eqs 30–31 would divide by zero)."""
    omega_h_table1 = np.sqrt(4 * 1.5e9 * 2.206e-4**2 / (20 * 1.5e-5))
    omega_h_eq39 = np.sqrt(PARAMS.plant.hydraulic_stiffness_1_s2)
    assert omega_h_table1 == pytest.approx(986.6, rel=1e-3)
    assert omega_h_eq39 == pytest.approx(5600.0)
    a, b, c = closed_loop_matrices(PARAMS)
    assert (c @ b).item() == 0.0 and (c @ a @ b).item() == 0.0  # relative degree > 2
    # Table 1's K_sv·ω_sv² would miss eq 39's 4.263e8 at the 4th digit
    g = PARAMS.controller
    assert 16.5 * 2430**2 * g.k_a * g.k_p * g.k_f == pytest.approx(4.265e8, rel=2e-4)


def test_a_params_file_whose_closed_loop_is_unstable_is_refused_naming_the_section(
    tmp_path: Path,
) -> None:
    """load_params checks the file against the model (eq 39 with K_p = 1000 has poles in the
    right half plane); the shipped file passes the same check."""
    bad = tmp_path / "params.yaml"
    bad.write_text("plant: {}\ncontroller: {k_p: 1000.0}\n")
    with pytest.raises(ConfigError, match=r"params\.yaml: controller: .* unstable \(pole at 3184"):
        load_params(bad)
    assert check_closed_loop_stable(PARAMS) is PARAMS
