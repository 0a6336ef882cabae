"""The pressure test (control/evidence/pressure.py) and the increment product it tests
(control/evidence/increments.py)."""

from __future__ import annotations

import numpy as np
import pytest

from ehpss_hil.control.evidence.increments import Increments
from ehpss_hil.control.evidence.pressure import PressureTest
from ehpss_hil.control.tuning import ControlTuning
from ehpss_hil.physics.faults import FaultState
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import PlantStepper

PARAMS = load_params()
TS = 1e-3


def _run(
    k_q: float,
    k_dft: float,
    n: int = 400,
    noise_pa: float = 1e4,
    converge: int = 0,
    theta_l_wrong: int = 0,
) -> list[bool]:
    """Random coil current through the plant; the monitor sees the echo, P_L and θ_pos.

    ``converge``: θ_pos moves linearly from 0.96 to k_Q·k_DFT over that many samples (an
    estimate still converging); ``theta_l_wrong``: k̂_LOE is 1 instead of 0.8 for that many."""
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_loe=0.8, k_q=k_q, k_dft=k_dft))
    mon = PressureTest(PARAMS.plant, TS)
    rng = np.random.default_rng(7)
    out = []
    current = 0.0
    target = k_q * k_dft
    for k in range(n):
        p = plant.load_pressure_pa + noise_pa * rng.standard_normal()
        theta = target + (0.96 - target) * max(0.0, 1.0 - k / converge) if converge else target
        mon.update(current, p, theta_l=1.0 if k < theta_l_wrong else 0.8, theta_pos=theta)
        out.append(mon.flow_fault)
        current = 1e-4 * rng.standard_normal()
        plant.step(current)
    return out


def test_flow_gain_loss_is_recognized() -> None:
    decided = _run(k_q=0.7, k_dft=1.0)
    assert decided[-1] and not decided[20]  # needs evidence first (≥ 30 ms), then H_Q
    assert sum(decided[-200:]) == 200


def test_sensor_drift_is_not_taken_for_a_flow_loss() -> None:
    assert not any(_run(k_q=1.0, k_dft=0.7))
    assert not any(_run(k_q=1.0, k_dft=0.0))  # a failed sensor is never a flow-gain loss


def test_evidence_is_kept_while_the_product_converges() -> None:
    """A deviation still converging (0.96 → 0.7 over 40 samples) is one hypothesis pair: the
    window is not emptied as θ_pos moves, so H_Q comes once the minimum evidence is in (a window
    restarted at every 0.05 of movement could not decide before sample 70)."""
    decided = _run(k_q=0.7, k_dft=1.0, converge=40)
    first = decided.index(True)
    assert 30 <= first < 60
    assert all(decided[first:])


def test_evidence_taken_before_k_loe_was_identified_counts_with_the_identified_value() -> None:
    """The window holds k̂_LOE-free sums: samples taken while k̂_LOE was still 1 (a power-on LOE
    of 0.8 not identified yet) are weighed with 0.8 once it is known — the same Λ as a monitor
    that knew 0.8 from the start."""
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_loe=0.8, k_q=1.0, k_dft=0.7))
    late = PressureTest(PARAMS.plant, TS)
    known = PressureTest(PARAMS.plant, TS)
    rng = np.random.default_rng(3)
    current = 0.0
    for k in range(60):
        p = plant.load_pressure_pa + 1e4 * rng.standard_normal()
        late.update(current, p, theta_l=1.0 if k < 25 else 0.8, theta_pos=0.7)
        known.update(current, p, theta_l=0.8, theta_pos=0.7)
        current = 1e-4 * rng.standard_normal()
        plant.step(current)
    assert known.llr < -ControlTuning().flow_gain_threshold
    assert late.llr == pytest.approx(known.llr, rel=1e-9)
    assert not late.flow_fault and late.sensor_decided


def test_no_decision_without_a_deviation() -> None:
    assert not any(_run(k_q=0.98, k_dft=1.0))


def test_product_estimate_is_offset_free() -> None:
    mon = Increments(PARAMS.plant, TS, scale_m=1.52e-3)
    kc = PARAMS.plant.velocity_gain_1_s
    x, prev = 5e-4, 1.52e-3  # a level offset the increments do not see
    for k in range(300):
        spool = 1.52e-3 * np.cos(5 * k * TS)
        x += 0.7 * kc * 0.5 * (spool + prev) * TS  # trapezoid, like the monitor
        prev = spool
        mon.product(x, spool)
    assert mon.theta_prod == pytest.approx(0.7, abs=0.005)


def test_hold_off_takes_no_evidence_and_keeps_the_decision() -> None:
    """After a gap the pressure model is stepped on guessed currents: for ``hold_off(n)``
    updates no evidence enters the window and the decision stands; then it resumes."""
    mon = PressureTest(PARAMS.plant, TS)
    rng = np.random.default_rng(3)
    for _ in range(50):  # a deviating product: the window fills
        mon.update(1e-4 * rng.standard_normal(), 1e4 * rng.standard_normal(), 1.0, 0.5)
    w, llr, fault = mon._w, mon.llr, mon.flow_fault
    assert w > 0.0
    mon.hold_off(5)
    for _ in range(5):  # a wild prediction error would otherwise swing the statistic
        mon.update(1e-2, 5e6, 1.0, 0.5)
        assert (mon._w, mon.llr, mon.flow_fault) == (w, llr, fault)
    mon.update(1e-4, 0.0, 1.0, 0.5)
    assert mon._w != w


def test_pressure_test_and_product_take_their_constants_from_the_tuning() -> None:
    """One home per constant: the window, the product's clip and the failed-sensor bound come
    from ControlTuning (the monitor once had its own 0.1 s window against the tuning's 0.5 s)."""
    import math
    from dataclasses import replace

    from ehpss_hil.control.tuning import ControlTuning

    tun = replace(
        ControlTuning(), flow_gain_window_s=0.2, k_dft_limits=(0.0, 1.3), flow_gain_min_deviation=0.07
    )
    mon = Increments(PARAMS.plant, TS, scale_m=1.52e-3, tuning=tun)
    test = PressureTest(PARAMS.plant, TS, tuning=tun)
    assert test._d == math.exp(-TS / 0.2)
    assert test.min_deviation == 0.07
    # a position moving three times as fast as the spool integral says: the product clips at 1.3
    x = 0.0
    for k in range(400):
        spool = 1.52e-3 * math.sin(5e-3 * k * 5)
        x += 3.0 * TS * PARAMS.plant.velocity_gain_1_s * spool
        mon.product(x, spool)
    assert mon.theta_prod == 1.3


def test_a_product_that_falls_below_the_failed_sensor_bound_ends_h_q_even_when_held() -> None:
    """H_Q decided, then the product falls to 0 (the sensor failed) while evidence is held off:
    H_Q ends at once and k̂_Q is 1, not 0 (mmac divided the position by k̂_Q = 0: a scenario
    at 10.5 Hz, found by the config property test)."""
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_loe=0.8, k_q=0.7, k_dft=1.0))
    mon = PressureTest(PARAMS.plant, TS)
    rng = np.random.default_rng(7)
    current = 0.0
    for _ in range(400):
        mon.update(current, plant.load_pressure_pa + 1e4 * rng.standard_normal(), 0.8, 0.7)
        current = 1e-4 * rng.standard_normal()
        plant.step(current)
    assert mon.flow_fault and mon.k_q == 0.7
    mon.hold_off(10)
    assert mon.update(current, plant.load_pressure_pa, 0.8, 0.0) == 1.0
    assert not mon.flow_fault and mon.k_q == 1.0
