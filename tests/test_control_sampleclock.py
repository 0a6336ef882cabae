"""The sample clock: cycles without data, redone spans and superseded samples give the banks the
same per-sample predictions as an unbroken stream (plant in the loop, one sample of transport
delay, no noise)."""

from __future__ import annotations

import math

import pytest

from ehpss_hil.control.base import Measurement
from ehpss_hil.control.predictors import ModelPosition, ValvePredictor
from ehpss_hil.control.sampleclock import RESYNC_SAMPLES, SampleClock, resync_span
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import PlantStepper

PARAMS = load_params()
TS = 1e-3


def _run(missing: set[int], n: int = 60) -> tuple[list[float], list[float], list[bool]]:
    """Per sample k: the commanded spool v and x̂ after the clock took sample k (or a dead cycle
    when k is missing), with commands computed as a sine and applied one sample later."""
    plant = PlantStepper(PARAMS, TS)
    clock = SampleClock(
        ValvePredictor(PARAMS.plant, TS), ModelPosition(PARAMS.plant, TS, anchor_rate_1_s=0.0)
    )
    cmd = [2e-4 * math.sin(0.2 * k) for k in range(n)]
    applied_prev, last_seen = 0.0, -1
    vs, xs, gaps = [], [], []
    for k in range(n):
        if k in missing:
            clock.dead_cycle(1.0)
            gaps.append(False)
        else:
            m = Measurement(
                position_m=plant.position_m,
                spool_m=plant.spool_actual_m,
                coil_current_a=applied_prev,
                samples=k - last_seen if k else 0,
            )
            adv = clock.sample(m, 1.0, None)
            gaps.append(adv.gap)
            last_seen = k
        vs.append(clock.valve.v)
        xs.append(clock.xhat.x)
        clock.commanded(cmd[k], True)
        applied_prev = plant.step(cmd[k - 1] if k else 0.0)
    return vs, xs, gaps


def test_a_gap_of_lost_samples_is_redone_on_the_commands_sent() -> None:
    v0, x0, _ = _run(set())
    v1, x1, gaps = _run({20, 21, 22})
    assert gaps[23] and not gaps[24]
    for k in range(23, 60):  # from the sample after the gap on: the unbroken stream's values
        assert v1[k] == pytest.approx(v0[k], rel=1e-9, abs=1e-15)
        assert x1[k] == pytest.approx(x0[k], rel=1e-9, abs=1e-15)


def test_a_superseded_sample_observed_keeps_the_stream() -> None:
    """Samples k and k+1 arrive in one cycle: observing k, then stepping on k+1, equals the
    unbroken stream."""
    plant = PlantStepper(PARAMS, TS)
    ref = SampleClock(ValvePredictor(PARAMS.plant, TS), ModelPosition(PARAMS.plant, TS, 0.0))
    clk = SampleClock(ValvePredictor(PARAMS.plant, TS), ModelPosition(PARAMS.plant, TS, 0.0))
    applied_prev, held = 0.0, None
    for k in range(40):
        m = Measurement(
            position_m=plant.position_m,
            spool_m=plant.spool_actual_m,
            coil_current_a=applied_prev,
            samples=1 if k else 0,
        )
        ref.sample(m, 1.0, None)
        if k == 10:
            held = Measurement(m.position_m, m.spool_m, m.coil_current_a, samples=1)
        elif k == 11:
            assert held is not None
            clk.observe(held, 1.0)
            clk.sample(m, 1.0, None)
        else:
            clk.sample(m, 1.0, None)
        c = 1e-4 * math.cos(0.3 * k)
        ref.commanded(c, True)
        clk.commanded(c, True)
        applied_prev = plant.step(c)
        if k >= 11:
            assert clk.xhat.x == pytest.approx(ref.xhat.x, rel=1e-12, abs=1e-18)
            assert clk.valve.v == pytest.approx(ref.valve.v, rel=1e-12, abs=1e-18)


def test_resync_only_within_the_counter_range() -> None:
    assert not resync_span(1, 0) and not resync_span(0, 3)
    assert resync_span(2, 0) and resync_span(1, 1) and resync_span(RESYNC_SAMPLES, 14)
    assert not resync_span(RESYNC_SAMPLES + 1, 0) and not resync_span(3, RESYNC_SAMPLES)


def test_the_first_sample_after_a_reset_seeds_x_hat() -> None:
    clock = SampleClock(ValvePredictor(PARAMS.plant, TS), ModelPosition(PARAMS.plant, TS, 0.0))
    clock.xhat.x = 0.3
    adv = clock.sample(Measurement(position_m=2e-3, samples=0), 1.0, None)
    assert adv.x == clock.xhat.x == 2e-3 and not clock.seed
