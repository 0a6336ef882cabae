"""The level-jump detector (control/evidence/jump.py): a position reading that moves by more than any
flow gain in [0, 1] explains is a sensor event, with the sensor's gain ratio; a flow-gain loss,
however abrupt, never is. Pure logic: samples are counted, the noise is seeded."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ehpss_hil.control.evidence.jump import LevelJump
from ehpss_hil.control.tuning import ControlTuning

MIN_SAMPLES = ControlTuning().jump_min_samples

STEP_M = 5e-6  # piston travel per sample at the nominal flow gain (5 mm/s at 1 kHz)
NOISE_M = 1e-6


def _run(
    n: int, k_dft: list[float], k_q: list[float], x0: float = 1e-3, seed: int = 1
) -> tuple[list[bool], LevelJump]:
    """``n`` samples of a piston moving at ``k_q[k]`` times the nominal speed, read through
    ``k_dft[k]`` with white noise; the spool integral advances at the nominal speed."""
    rng = np.random.default_rng(seed)
    j = LevelJump(10)
    x, integral, out = x0, 0.0, []
    for k in range(n):
        x += k_q[k] * STEP_M
        integral += STEP_M
        y = k_dft[k] * x + NOISE_M * rng.standard_normal()
        out.append(j.update(y, integral, 1.0, True))
    return out, j


def test_a_healthy_sensor_never_jumps() -> None:
    for seed in range(5):
        out, _ = _run(3000, [1.0] * 3000, [1.0] * 3000, seed=seed)
        assert not any(out)


def test_a_flow_gain_loss_is_not_a_jump_however_abrupt() -> None:
    k_q = [1.0] * 500 + [0.0] * 500 + [0.5] * 1000  # the flow stops, then half of it returns
    out, _ = _run(2000, [1.0] * 2000, k_q)
    assert not any(out)


@pytest.mark.parametrize("new_gain", [0.8, 0.5, 1.2])
def test_a_sensor_gain_step_is_a_jump_with_its_ratio(new_gain: float) -> None:
    k_dft = [1.0] * 500 + [new_gain] * 500
    out, j = _run(1000, k_dft, [1.0] * 1000)
    assert [k for k, hit in enumerate(out) if hit] == [500]
    assert j.ratio == pytest.approx(new_gain, abs=0.01)


def test_a_gain_step_near_zero_is_unseen_and_gives_no_ratio() -> None:
    """At x ≈ 10 µm a 20 % gain step moves the reading by 2 µm: inside the noise band, and
    the error it causes is as small."""
    out, _ = _run(1000, [1.0] * 500 + [0.8] * 500, [0.0] * 1000, x0=1e-5)
    assert not any(out)


def test_no_judgement_before_the_noise_is_known_and_across_a_broken_chain() -> None:
    j = LevelJump(10)
    assert not j.update(1e-3, 0.0, 1.0, True)  # first sample: no increment
    for k in range(MIN_SAMPLES - 2):
        assert not j.update(1e-3 + NOISE_M * (-1) ** k, 0.0, 1.0, True)
    assert not j.update(0.5e-3, 0.0, 1.0, True)  # a 500 µm step, but σ̂ is not known yet
    for k in range(50):
        j.update(0.5e-3 + NOISE_M * (-1) ** k, 0.0, 1.0, True)
    j.break_chain()  # samples missed: the next one only restarts the increments
    assert not j.update(1.5e-3, 0.0, 1.0, True)
    assert j.update(1.0e-3, 0.0, 1.0, True)  # a jump within the new chain is seen
    assert math.isfinite(j.ratio)


def test_the_gain_before_a_jump_is_used_until_theta_prod_settles_again() -> None:
    """After a jump θ_prod spans it (0 here): the band must not collapse to nothing, or
    every ordinary increment after it would look like a jump."""
    j = LevelJump(10)
    y, integral = 1e-3, 0.0
    for k in range(100):
        y += STEP_M + NOISE_M * (-1) ** k
        integral += STEP_M
        j.update(y, integral, 1.0, True)
    y *= 0.7  # the gain step
    integral += STEP_M
    assert j.update(y, integral, 1.0, True)
    hits = 0
    for k in range(100):
        y += 0.7 * STEP_M + NOISE_M * (-1) ** k
        integral += STEP_M
        hits += j.update(y, integral, 0.0, False)  # θ_prod garbage, not settled
    assert hits == 0
