"""A spool overlap the plant shows (control/evidence/overlap.py): learned from the stretches the
spool spends inside the uncertainty set's band while the sensor is trusted, never from a reading
that repeats itself to the bit (a stuck sensor), and then x̂ integrates no spool inside the band.

Before, x̂ integrated the spool chattering inside a 0.15 mm overlap while the loop held a step:
x̂ travelled 30 µm, the reading did not, and the position bank switched to its failed-sensor
model at 0.33 s; the loop then ran on x̂ (86.8 µm RMS against nrc's 56.8)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.control.adaptive import MmacController
from ehpss_hil.control.controllers import LoopBase
from ehpss_hil.control.evidence.overlap import SpoolOverlap
from ehpss_hil.control.predictors import ModelPosition
from ehpss_hil.control.registry import make_controller
from ehpss_hil.control.tuning import ControlTuning
from ehpss_hil.physics.load import load_params
from ehpss_hil.report.metrics import compute_metrics, does_harm, harm_limits
from ehpss_hil.scenario import Scenario, load_scenario
from ehpss_hil.sim import lockstep, run_scenario

PARAMS = load_params()
TS = 1e-3
KC = PARAMS.plant.velocity_gain_1_s
T = ControlTuning()
NOISE_M = 1e-6


def _feed(ov: SpoolOverlap, spool_m: float, readings: np.ndarray, healthy: bool = True) -> list[bool]:
    """One sample per reading with the spool held at ``spool_m``; what :meth:`update` returned."""
    return [ov.update(spool_m, float(y), healthy, 1.0, NOISE_M) for y in readings]


def _travel_samples(spool_m: float, travel_m: float) -> int:
    return int(np.ceil(travel_m / (KC * TS * abs(spool_m)))) + 2


def test_a_reading_that_stands_still_while_x_hat_travels_in_band_shows_the_overlap() -> None:
    ov = SpoolOverlap(KC, TS, T)
    spool = 0.5 * T.spool_overlap_max_m
    n = 8 * _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)  # eight stretches' worth
    y = 1e-3 + np.random.default_rng(1).normal(0.0, NOISE_M, n)
    shown = _feed(ov, spool, y)
    assert shown.count(True) == 1 and ov.gain < 0.25


def test_a_reading_that_follows_x_hat_in_band_shows_no_overlap() -> None:
    ov = SpoolOverlap(KC, TS, T)
    spool = 0.5 * T.spool_overlap_max_m
    n = 6 * _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)
    y = 1e-3 + KC * TS * spool * np.arange(n) + np.random.default_rng(2).normal(0.0, NOISE_M, n)
    assert not any(_feed(ov, spool, y)) and ov.gain == 1.0


def test_a_stuck_reading_is_no_evidence_of_an_overlap() -> None:
    """Bit for bit the same reading: a sensor that stuck while the loop held still."""
    ov = SpoolOverlap(KC, TS, T)
    spool = 0.5 * T.spool_overlap_max_m
    n = 6 * _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)
    assert not any(_feed(ov, spool, np.full(n, 1e-3))) and ov.gain == 1.0


def test_a_reading_that_freezes_inside_a_stretch_is_no_evidence_of_an_overlap() -> None:
    """A short stretch while the noise estimate is still near 0 (the first samples), then one in
    which the reading freezes to the bit after a few live samples: neither is evidence."""
    ov = SpoolOverlap(KC, TS, T)
    spool = 0.5 * T.spool_overlap_max_m
    rng = np.random.default_rng(4)
    shown = [
        ov.update(spool, 1e-3 + NOISE_M * rng.standard_normal(), True, 1.0, 0.05 * NOISE_M) for _ in range(6)
    ]
    shown.append(ov.update(2.0 * spool / 0.5, 1e-3, True, 1.0, NOISE_M))  # out of the band: closed
    n = 3 * _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)
    y = 1e-3 + rng.normal(0.0, NOISE_M, n)
    y[4:] = y[3]
    shown += _feed(ov, spool, y)
    assert not any(shown) and ov.gain == 1.0


def test_a_reading_that_jumps_against_x_hat_inside_a_stretch_is_no_evidence_of_an_overlap() -> None:
    """A sensor gain stepping down while the loop holds still moves the reading against x̂: no
    overlap explains that (``drift-ramp-square``'s drift step at 1.83 s showed one)."""
    ov = SpoolOverlap(KC, TS, T)
    spool = 0.5 * T.spool_overlap_max_m
    per = _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)
    rng = np.random.default_rng(5)
    x = KC * TS * spool * np.arange(8 * per)  # a lapped plant: the piston moves as x̂ does
    y = 1e-3 + x + rng.normal(0.0, NOISE_M, x.size)
    y -= 30 * NOISE_M * ((np.arange(x.size) + per // 2) // per)  # a step down inside each stretch
    assert not any(_feed(ov, spool, y)) and ov.gain == 1.0


def test_a_reading_frozen_for_a_window_inside_a_stretch_is_no_evidence_of_an_overlap() -> None:
    """Live for most of each stretch, then M readings alike at its end (qualification run 1330:
    a sensor stuck 36 samples before a 334-sample stretch ended showed an overlap)."""
    ov = SpoolOverlap(KC, TS, T)
    spool = 0.1 * T.spool_overlap_max_m
    per = _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)
    y = 1e-3 + np.random.default_rng(6).normal(0.0, NOISE_M, 8 * per)
    for k in range(8):  # the last 2M readings of each stretch's worth alike
        end = (k + 1) * per
        y[end - 2 * T.increment_window : end] = y[end - 2 * T.increment_window - 1]
    assert not any(_feed(ov, spool, y)) and ov.gain == 1.0


def test_a_reading_that_moves_against_x_hat_in_every_stretch_is_no_overlap() -> None:
    """Each stretch within the noise, all of them together well below a share of 0 (a piston
    settling after a trapezoid's corner, qualification run 219): no overlap explains it."""
    ov = SpoolOverlap(KC, TS, T)
    spool = 0.5 * T.spool_overlap_max_m
    per = _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)
    k = np.arange(8 * per)
    rng = np.random.default_rng(7)
    y = 1e-3 - 0.6 * KC * TS * spool * k + rng.normal(0.0, 0.2 * NOISE_M, k.size)
    assert not any(_feed(ov, spool, y)) and ov.gain == 1.0


@pytest.mark.parametrize("case", ["outside the band", "not healthy"])
def test_no_evidence_outside_the_band_or_while_the_channel_is_not_healthy(case: str) -> None:
    ov = SpoolOverlap(KC, TS, T)
    spool = (2.0 if case == "outside the band" else 0.5) * T.spool_overlap_max_m
    n = 6 * _travel_samples(spool, T.overlap_evidence_snr * NOISE_M)
    y = 1e-3 + np.random.default_rng(3).normal(0.0, NOISE_M, n)
    assert not any(_feed(ov, spool, y, healthy=case != "not healthy")) and ov.gain == 1.0


def test_x_hat_integrates_the_band_at_its_gain_and_the_spool_outside_it_in_full() -> None:
    band = T.spool_overlap_max_m
    xh = ModelPosition(PARAMS.plant, TS, 0.0, band)
    xh.band_gain = 0.0
    for _ in range(10):
        xh.integrate(0.5 * band)
    assert xh.x == 0.0 and xh.last_spool == 0.5 * band
    for _ in range(10):
        xh.integrate(2.0 * band)
    # the trapezoid's first step averages the in-band (0) and the outside spool
    assert xh.x == pytest.approx(KC * TS * 2.0 * band * 9.5, rel=1e-12)


def _scenario(name: str) -> Scenario:
    return load_scenario(PROJECT_ROOT / "scenarios" / name)


@pytest.fixture
def made(monkeypatch: pytest.MonkeyPatch) -> list[LoopBase]:
    """The controllers the lockstep simulator makes in the test, in order."""
    out: list[LoopBase] = []

    def keep(*args: Any) -> LoopBase:
        out.append(make_controller(*args))
        return out[-1]

    monkeypatch.setattr(lockstep, "make_controller", keep)
    return out


def test_a_hold_on_an_overlapped_valve_does_no_harm_and_the_overlap_is_learned(made: list[LoopBase]) -> None:
    sc = _scenario("mismatch/nl-overlap-hold.yaml")
    mm = compute_metrics(run_scenario(sc, "mmac", PARAMS))
    nrc = compute_metrics(run_scenario(sc, "nrc", PARAMS))
    assert not does_harm(mm, nrc), (mm, harm_limits(nrc))
    assert isinstance(made[0], MmacController) and made[0].xhat.band_gain < T.overlap_shown_below


def test_an_overlap_shown_is_kept_across_a_fail_safe_reset(made: list[LoopBase]) -> None:
    """Leaving the fail-safe does not change the valve: x̂ goes on integrating the band at the
    share learned (as the plant's flow gain and pressure baseline are kept)."""
    run_scenario(_scenario("mismatch/nl-overlap-hold.yaml"), "mmac", PARAMS)
    c = made[0]
    assert isinstance(c, MmacController)
    g = c.xhat.band_gain
    assert g < T.overlap_shown_below
    c.reset()
    assert c.xhat.band_gain == g and c.evidence.overlap.gain == g
    assert make_controller("mmac", PARAMS, TS).xhat.band_gain == 1.0  # a new controller: none


@pytest.mark.parametrize(
    "name",
    [
        "envelope/stuck-square.yaml",
        "envelope/stuck-trapezoid.yaml",
        "envelope/drift-then-stuck-square.yaml",
        "envelope/drift-ramp-square.yaml",
        "case1-loe.yaml",
    ],
)
def test_no_overlap_is_learned_on_a_critically_lapped_plant(name: str, made: list[LoopBase]) -> None:
    """The linear plant passes flow at any spool: a stuck sensor held still, a drift, an LOE."""
    run_scenario(_scenario(name), "mmac", PARAMS)
    assert isinstance(made[0], MmacController) and made[0].xhat.band_gain == 1.0
