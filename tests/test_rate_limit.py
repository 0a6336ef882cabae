"""The rate plausibility of SENSOR_POS Position (codec/ratelimit.py): what a real sensor does
passes (the fastest motion through k_DFT 2.5, lost samples, a gain step, a failure to 0, a new
level after one sample), a reading no sensor produced does not; through FrameCodec.classify."""

from __future__ import annotations

import random

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.codec.ratelimit import K_DFT_MAX, RateLimit, position_step_bound_m
from ehpss_hil.physics.load import load_params

SPEED = load_params().plant.piston_speed_max_m_s
STEP = position_step_bound_m(SPEED, 1e-3)


def test_the_bound_is_the_plants_speed_through_the_largest_gain() -> None:
    assert 0.030 < SPEED < 0.035  # K_c × spool stroke ≈ 33 mm/s
    lim = RateLimit(STEP)
    y = 0.0
    for c in range(40):  # the fastest piston read through k_DFT 2.5, every sample
        y += SPEED * 1e-3 * K_DFT_MAX
        assert lim.check(y, c & 0xF)
    assert lim.check(y + 3 * SPEED * 1e-3 * K_DFT_MAX, (40 + 2) & 0xF)  # 2 samples lost


def test_sensor_faults_pass_wild_readings_do_not() -> None:
    lim = RateLimit(STEP)
    assert lim.check(0.2, 0) and lim.check(0.0, 1)  # a failed sensor reads 0: never rejected
    assert not lim.check(0.001, 2) and lim.check(0.001, 3)  # back from 0: one sample lost
    assert lim.check(0.0025, 3)  # k_DFT 1 -> 2.5 at 1 mm
    assert not lim.check(0.3, 4)  # one wild reading
    assert lim.check(0.0025, 5) and lim.rejected == 2  # the next real one is accepted
    assert not lim.check(0.0525, 6)  # a bias step of 50 mm: the first reading is rejected,
    assert lim.check(0.0526, 7)  # the second, close to it, is a new level
    assert lim.check(0.0527, 8)


def test_random_positions_rarely_pass() -> None:
    """Readings spread over the DBC range between real ones at 1 mm: ≈ 2·(step + 1.5 mm)/1 m."""
    rng = random.Random(7)
    lim = RateLimit(STEP)
    passed = 0
    n = 20000
    for k in range(n):
        lim.check(0.001, (2 * k) & 0xF)
        passed += lim.check(rng.uniform(-0.5, 0.5), (2 * k + 1) & 0xF)
    assert passed / n < 2 * (STEP + 1.5 * 0.001) * 1.3


def test_classify_counts_a_jump_as_out_of_range() -> None:
    tx, rx = FrameCodec(), FrameCodec()
    rx.limit_rate("SENSOR_POS", "Position", STEP)
    verdicts = [
        rx.classify(tx.encode("SENSOR_POS", {"Position": p, "Spool": 0.0})).verdict
        for p in (0.001, 0.00101, 0.4, 0.00102, 0.00103)
    ]
    assert verdicts == [Verdict.OK, Verdict.OK, Verdict.OUT_OF_RANGE, Verdict.OK, Verdict.OK]
    assert rx.counts_by_name["SENSOR_POS"][Verdict.OUT_OF_RANGE] == 1
