"""The still-sensor check (control/evidence/still.py): a position sensor that does not move while
the spool sits at its stop is dead; a live one, even at a low gain, is not. Pure logic, no
timing: samples are counted."""

from __future__ import annotations

import pytest

from ehpss_hil.control.evidence.still import StillSensor
from ehpss_hil.control.tuning import ControlTuning

MIN_TRAVEL_M = ControlTuning().still_min_travel_m
STILL_FRACTION = ControlTuning().still_fraction

K_C = 3.3  # 1/s: 10 mm of spool move the model position 33 mm/s
TS = 1e-3
STOP_M = 0.01


def _phase(
    s: StillSensor, gain: float, samples: int, x0: float = 1e-3, y0: float = 2e-3
) -> list[float | None]:
    """``samples`` at the stop; the sensor moves by ``gain`` times the spool integral."""
    out: list[float | None] = []
    travel = 0.0
    for _ in range(samples):
        travel += K_C * TS * STOP_M
        out.append(s.update(True, STOP_M, y0 + gain * travel, x0 + travel))
    return out


def test_a_sensor_that_stands_still_is_found_dead_once_with_the_model_position() -> None:
    s = StillSensor(K_C, TS)
    out = _phase(s, 0.0, 40)
    hits = [(k, x) for k, x in enumerate(out) if x is not None]
    n_min = MIN_TRAVEL_M / (K_C * TS * STOP_M)  # samples to cover the minimum travel
    step = K_C * TS * STOP_M
    assert len(hits) == 1
    k, x = hits[0]
    assert k == pytest.approx(n_min, abs=1.0)
    # x̂ at the phase's first sample plus the spool integral of the k samples after it
    assert x == pytest.approx(1e-3 + step + k * step)


@pytest.mark.parametrize("gain", [0.3, 0.1, 2 * STILL_FRACTION])
def test_a_live_sensor_is_not_dead_whatever_its_gain(gain: float) -> None:
    s = StillSensor(K_C, TS)
    assert all(x is None for x in _phase(s, gain, 200))


def test_each_stop_phase_is_judged_afresh_and_leaving_the_stop_ends_it() -> None:
    s = StillSensor(K_C, TS)
    assert all(x is None for x in _phase(s, 0.0, 5))  # too short a phase
    assert s.update(False, 0.0, 2e-3, 1e-3) is None
    assert all(x is None for x in _phase(s, 0.0, 5))  # the travel started over
    assert s.update(False, 0.0, 2e-3, 1e-3) is None
    assert sum(x is not None for x in _phase(s, 0.0, 40)) == 1
    s.reset()
    assert sum(x is not None for x in _phase(s, 0.0, 40)) == 1


def test_a_sensor_that_dies_during_a_long_stop_phase_is_caught_in_the_next_stretch() -> None:
    """Live for the first 30 samples of the phase, then frozen: found dead within two
    stretches of the minimum travel after it froze, with the model position the spool
    integral over the whole phase."""
    s = StillSensor(K_C, TS)
    step = K_C * TS * STOP_M
    n_min = MIN_TRAVEL_M / step
    y, hits = 2e-3, []
    for k in range(200):
        if k < 30:
            y += 0.8 * step
        x = s.update(True, STOP_M, y, 1e-3 + (k + 1) * step)
        if x is not None:
            hits.append((k, x))
    assert len(hits) == 1
    k, x = hits[0]
    assert 30 <= k <= 30 + 2 * n_min + 1
    assert x == pytest.approx(1e-3 + (k + 1) * step)
