"""The pressure test (control/evidence/pressure.py) and the increment product it tests
(control/evidence/increments.py)."""

from __future__ import annotations

import numpy as np
import pytest

from ehpss_hil.control.evidence.baseline import PressureBaseline
from ehpss_hil.control.evidence.increments import Increments
from ehpss_hil.control.evidence.likelihood import PressureWindow
from ehpss_hil.control.evidence.loadpressure import LoadPressure
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
    that knew 0.8 from the start. A drift of 0.6, beyond the velocity-gain uncertainty (0.3): one
    inside it is not decided before the plant's pressure gain is learned (``fault_possible``)."""
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_loe=0.8, k_q=1.0, k_dft=0.6))
    late = PressureTest(PARAMS.plant, TS)
    known = PressureTest(PARAMS.plant, TS)
    rng = np.random.default_rng(3)
    current = 0.0
    llr_late, llr_known = [], []
    for k in range(60):
        p = plant.load_pressure_pa + 1e4 * rng.standard_normal()
        # the position bank's model at the sensor's gain, as a drift of 0.6 makes it
        late.update(current, p, theta_l=1.0 if k < 25 else 0.8, theta_pos=0.6, theta_level=0.6)
        known.update(current, p, theta_l=0.8, theta_pos=0.6, theta_level=0.6)
        llr_late.append(late.llr)
        llr_known.append(known.llr)
        current = 1e-4 * rng.standard_normal()
        plant.step(current)
    assert min(llr_known) < -ControlTuning().flow_gain_threshold
    # from the sample k̂_LOE is known on, the same Λ sample for sample (once H_D is decided the
    # product sits at the sensor gain it stands at: nothing left to test, Λ = 0 in both)
    assert llr_late[25:] == pytest.approx(llr_known[25:], rel=1e-9)
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
    w, llr, fault = mon.window.w, mon.llr, mon.flow_fault
    assert w > 0.0
    mon.hold_off(5)
    for _ in range(5):  # a wild prediction error would otherwise swing the statistic
        mon.update(1e-2, 5e6, 1.0, 0.5)
        assert (mon.window.w, mon.llr, mon.flow_fault) == (w, llr, fault)
    mon.update(1e-4, 0.0, 1.0, 0.5)
    assert mon.window.w != w


def test_the_load_pressure_evidence_counts_its_hold_off_and_drops_evidence_about_another_plant() -> None:
    """``LoadPressure``: a hold-off of n samples is n held samples; k̂_LOE is followed from the
    first healthy sample and a move beyond ``flow_gain_min_deviation`` of it is reported once;
    the window's product is the averaged product at its first sample, and a move off it counts
    only once the window held ``undecided_evidence`` times the minimum evidence."""
    t = ControlTuning()
    ev = LoadPressure(PARAMS.plant, TS, t)
    ev.hold_off(3)
    ev.hold_off(2)  # the longer hold-off stands
    assert [ev.held() for _ in range(4)] == [True, True, True, False]
    dev = t.flow_gain_min_deviation
    assert not ev.loe_moved(0.5, healthy=False)  # not settled: nothing to move from
    assert not ev.loe_moved(0.8, healthy=True)  # settles at 0.8
    assert not ev.loe_moved(0.8 * (1 + 0.9 * dev), healthy=True)
    assert ev.loe_moved(0.8 * (1 + 1.1 * dev), healthy=True)
    assert not ev.loe_moved(0.8 * (1 + 1.1 * dev), healthy=True)  # the new value is the reference
    n_undecided = t.undecided_evidence * t.flow_gain_min_evidence_s / TS
    ev.model.propagate(1e-3)
    ev.add(1e4, 0.7)  # the window is about a product at 0.7 from its first sample on
    for _ in range(int(n_undecided) - 1):  # the window's weight (samples) grows slower than one a sample
        ev.model.propagate(1e-3)
        ev.add(1e4, 0.9)
    assert not ev.undecided and not ev.moved_off(5.0)
    for _ in range(400):
        ev.model.propagate(1e-3)
        ev.add(1e4, 0.9)
    assert ev.undecided and ev.window.w >= n_undecided
    assert ev.moved_off(0.7 + 1.5 * dev) and not ev.moved_off(0.7 + 0.5 * dev)
    ev.restart()
    assert ev.window.w == 0.0 and not ev.undecided and not ev.moved_off(5.0)


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
    assert test.window.decay == math.exp(-TS / 0.2)
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


def _feed(
    pt: PressureTest,
    plant: PlantStepper,
    rng: np.random.Generator,
    n: int,
    theta: float,
    healthy: bool,
    noise_pa: float = 1e4,
) -> None:
    current = 0.0
    for _ in range(n):
        p = plant.load_pressure_pa + noise_pa * rng.standard_normal()
        pt.update(current, p, theta_l=1.0, theta_pos=theta, theta_level=theta, healthy=healthy)
        current = 1e-4 * rng.standard_normal()
        plant.step(current)


def _on_a_slow_plant() -> PressureTest:
    """A pressure test after 0.4 s on a plant 15 % slow from power-on."""
    rng = np.random.default_rng(5)
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_q=0.85))
    pt = PressureTest(PARAMS.plant, TS)
    _feed(pt, plant, rng, 400, 0.85, healthy=False)
    return pt


def test_a_plant_never_seen_at_the_model_gives_its_own_flow_gain_as_the_nominal() -> None:
    """A plant 15 % slow from power-on: the pressure leaves H_D and H_Q undecided within the
    uncertainty, so after ``undecided_evidence`` the product is the plant's flow gain (k_base),
    the nominal both hypotheses are judged against."""
    fresh = _on_a_slow_plant()
    assert fresh.k_base == pytest.approx(0.85, abs=1e-6)
    assert not fresh.attributed and not fresh.plant_seen


@pytest.mark.parametrize("baseline", [True, False], ids=["baseline-learned", "product-only"])
def test_a_deviation_after_the_plant_ran_at_the_model_is_a_change(baseline: bool) -> None:
    """Once the plant ran at the model's flow gain — a pressure baseline learned, or, where
    gaps held the baseline off (a loaded realtime host), the averaged product at 1 for
    ``plant_seen_s`` — a deviation the pressure leaves undecided (here a pressure reading 100×
    noisier) is a change, never the plant's flow gain: the realtime monitor test took a drift
    0.8 injected 0.36 s after an LOE for a plant 0.8 slow."""
    rng = np.random.default_rng(5)
    plant = PlantStepper(PARAMS, TS)
    seen = PressureTest(PARAMS.plant, TS)
    n_seen = round(ControlTuning().plant_seen_s / TS)
    _feed(seen, plant, rng, 400 if baseline else n_seen + 5, 1.0, healthy=baseline)
    assert seen.plant_seen and (seen.pressure_gain_learned if baseline else not seen.pressure_gain_learned)
    plant.set_faults(FaultState(k_q=0.85))
    _feed(seen, plant, rng, 400, 0.85, healthy=False, noise_pa=1e6)
    assert not seen.attributed and seen.k_base == 1.0


def test_the_product_seen_at_1_too_briefly_is_no_sight_of_the_plant() -> None:
    """The averaged product starts at 1 and passes through the band on its way to a power-on
    deviation: fewer than ``plant_seen_s`` of excited updates in a row are not the plant seen."""
    rng = np.random.default_rng(5)
    plant = PlantStepper(PARAMS, TS)
    pt = PressureTest(PARAMS.plant, TS)
    n_seen = round(ControlTuning().plant_seen_s / TS)
    _feed(pt, plant, rng, n_seen - 1, 1.0, healthy=False)
    assert not pt.plant_seen
    _feed(pt, plant, rng, 1, 1.0, healthy=False)
    assert pt.plant_seen


def test_a_recovery_keeps_what_is_known_of_the_plant_and_power_on_forgets_it() -> None:
    """:meth:`reset` (leaving the fail-safe) keeps the plant's flow gain, its sight at the
    model's and the pressure baseline: the plant did not change; :meth:`forget_plant` (a new
    controller) forgets them."""
    pt = _on_a_slow_plant()
    assert pt.k_base == pytest.approx(0.85, abs=1e-6)
    pt.reset()
    assert pt.k_base == pytest.approx(0.85, abs=1e-6) and pt.k_q == pt.k_base
    pt.forget_plant()
    pt.reset()
    assert (pt.k_base, pt.k_q, pt.plant_seen, pt.pressure_gain_learned) == (1.0, 1.0, False, False)


def test_the_pressure_baseline_is_the_healthy_gain_once_learned_within_its_limits() -> None:
    """``PressureBaseline``: 1 until ``baseline_min_s`` of samples, then the least-squares gain
    of P_L on u — clipped to ``baseline_limits``, and 1 inside ``baseline_deadband``; forgotten
    at power-on."""
    t = ControlTuning()
    n_min = round(t.baseline_min_s / TS)
    rng = np.random.default_rng(11)
    for true_gain, expect in ((1.3, 1.3), (1.02, 1.0), (3.0, t.baseline_limits[1])):
        b = PressureBaseline(TS, t)
        for k in range(n_min + 50):
            u = 2e4 * rng.standard_normal()
            b.learn(u, true_gain * u + 1e3 * rng.standard_normal())
            if k < n_min - 2:
                assert not b.learned and b.gain == 1.0
        assert b.learned
        assert b.gain == pytest.approx(expect, abs=0.01)
        b.forget()
        assert not b.learned and b.gain == 1.0


def test_h_q_is_judged_beside_the_sensor_gain_h_d_stands_at() -> None:
    """The sensor gain a later flow-gain change is judged beside: the one H_D stands at once the
    averaged product and the position bank's model (the reading's level) both show it, 1 before
    (an H_D decided on a product still converging is no gain to judge beside), 1 once withdrawn,
    and 1 for a failed sensor's (a campaign draw with H_D decided on a product of 0 divided by
    it)."""
    pt = PressureTest(PARAMS.plant, TS)
    assert pt.sensor_gain == 1.0
    pt.decide_sensor(1.3)
    assert pt.sensor_gain == 1.0  # not shown by the level yet
    for _ in range(60):
        pt.update(0.0, 0.0, theta_l=1.0, theta_pos=1.3, theta_level=1.3)
    assert pt.sensor_decided
    assert pt.sensor_gain == pytest.approx(1.3, abs=0.01)
    pt.withdraw_sensor()
    assert pt.sensor_gain == 1.0
    pt.decide_sensor(0.0)
    for _ in range(60):  # a failed sensor's product: no division by its gain
        pt.update(0.0, 0.0, theta_l=1.0, theta_pos=0.0, theta_level=0.0)
    assert pt.sensor_gain == 1.0
    assert not pt.flow_fault


def test_pressure_window_fits_and_ratio_match_the_weighted_sums() -> None:
    """The window's residual energy is Σw·(P_L − ĝ·u)² with the exponential weights, for the
    best ĝ clipped to the band; Λ favours the gain the data were made with, and is 0 where
    both bands hold the fitted gain."""
    rng = np.random.default_rng(7)
    n, d = 400, 0.99
    u = 2e4 * rng.standard_normal(n)
    p = 0.7 * u + 2e3 * rng.standard_normal(n)
    win = PressureWindow(d)
    for ui, pi in zip(u, p, strict=True):
        win.add(float(ui), float(pi))
    w = d ** np.arange(n - 1, -1, -1)
    assert win.w == pytest.approx(w.sum(), rel=1e-12)
    g_ls = float(np.sum(w * u * p) / np.sum(w * u * u))
    assert g_ls == pytest.approx(0.7, abs=0.02)
    for lo, hi, band, g in ((1.0, 1.0, 0.0, 1.0), (0.5, 0.6, 0.1, min(g_ls, 0.66)), (0.6, 0.8, 0.0, g_ls)):
        assert win.fit(lo, hi, band) == pytest.approx(float(np.sum(w * (p - g * u) ** 2)), rel=1e-9)
    assert win.llr(1.0, 0.7, 0.0, 0.0) > 50.0  # H_Q at 0.7 explains the data, H_D at 1 does not
    assert win.llr(0.7, 1.0, 0.0, 0.0) < -50.0
    assert win.llr(0.8, 0.6, 0.0, 0.2) == 0.0  # 0.7 lies within both bands: no evidence


@pytest.mark.parametrize("wander", [0.0, 0.15])
def test_a_product_whose_wander_reaches_the_failed_sensor_bound_is_no_flow_loss(wander: float) -> None:
    """The pressure says the flow gain fell to a quarter. With a clean product at 0.25 that is
    H_Q; with the same product wandering ±0.15 a sample (a dead reading under 15–20 µm of
    position noise gives products of 0.15–0.4) it is not: its average stands within
    ``product_spread`` mean steps of ``sensor_failed_below``, and a current divided by it drove
    a nonlinear campaign draw's piston from stop to stop (2.1 mm RMS)."""
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_loe=0.8, k_q=0.25))
    mon = PressureTest(PARAMS.plant, TS)
    rng = np.random.default_rng(3)
    current, entered = 0.0, False
    for _ in range(400):
        theta = 0.25 + wander * rng.uniform(-1.0, 1.0)
        mon.update(current, plant.load_pressure_pa + 1e4 * rng.standard_normal(), 0.8, theta)
        entered |= mon.flow_fault
        current = 1e-4 * rng.standard_normal()
        plant.step(current)
    assert entered == (wander == 0.0)
