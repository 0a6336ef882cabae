"""Estimates: the one owner of x̂, x0, y0 and the k̂ of mmac."""

from __future__ import annotations

import re

import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.control.estimates import Estimates
from ehpss_hil.control.predictors import ModelPosition
from ehpss_hil.physics.load import load_params

PARAMS = load_params()
TS = 1e-3


def _est(limit_m: float = 2e-3) -> Estimates:
    return Estimates(ModelPosition(PARAMS.plant, TS, 0.0), failed_below=0.15, rebase_limit_m=limit_m)


def test_rebase_keeps_x_hat_minus_x0_and_reads_y0_through_the_gain() -> None:
    e = _est()
    e.seed(1e-3)
    e.xhat.x = 1.2e-3  # the clock advanced x̂ by 0.2 mm since the seed
    e.rebase(0.8, trusted=True)
    assert e.x0 == pytest.approx(1e-3 / 0.8)
    assert e.xhat.x - e.x0 == pytest.approx(0.2e-3)


def test_rebase_refuses_an_untrusted_sensor_and_a_jump_beyond_the_limit() -> None:
    e = _est(limit_m=1e-3)
    e.seed(1e-3)
    e.rebase(0.5, trusted=False)
    assert (e.x0, e.xhat.x) == (1e-3, 1e-3)
    e.rebase(0.2, trusted=True)  # x0 would move by 4 mm
    assert (e.x0, e.xhat.x) == (1e-3, 1e-3)


def test_flow_hypothesis_enters_and_leaves_without_moving_the_sensor_reading() -> None:
    e = _est()
    e.seed(2e-3)
    e.set_channels(0.9, 0.8, False)
    e.enter_flow(1.6e-3, 0.8, 0.9)
    assert (e.k_q, e.k_dft) == (0.8, 1.0) and e.k_loe == pytest.approx(0.72)
    assert e.xhat.x == pytest.approx(2e-3) and e.x0 == pytest.approx(2.5e-3)
    e.leave_flow(1.6e-3, 0.05)  # a product below the failed-sensor threshold: read raw
    assert (e.xhat.x, e.x0) == (1.6e-3, 2e-3)


def test_restart_and_dead_placement() -> None:
    e = _est()
    e.set_channels(0.5, 0.5, False)
    e.enter_flow(1e-3, 0.7, 0.5)
    e.restart(3e-4)
    assert (e.xhat.x, e.x0, e.y0, e.k_q) == (3e-4, 3e-4, 3e-4, 1.0)
    e.place_dead(3e-4, 5e-4)
    assert (e.xhat.x, e.x0, e.y0) == (5e-4, 5e-4, 3e-4)


def test_no_other_control_module_places_x_hat_or_the_seed_point() -> None:
    """x̂ is placed only by Estimates; the sample clock and the loop only advance or anchor it."""
    pat = re.compile(r"\.x\s*[+\-]?=(?!=)|\b(?:est|estimates)\.[xy]0\s*=")
    owners = {"estimates.py", "sampleclock.py", "predictors.py"}
    found = []
    for path in (PROJECT_ROOT / "ehpss_hil" / "control").rglob("*.py"):
        if path.name in owners:
            continue
        text = path.read_text(encoding="utf-8")
        found += [f"{path.name}: {m.group(0)}" for m in pat.finditer(text)]
    # the base loop (nrc/oracle/smac/mmac-paper) sets x̂ to the sensor during its warm-up
    assert found == ["controllers.py: .x ="]
