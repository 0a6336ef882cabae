"""Regression per shipped scenario: mmac stays within the docs/design.md §11 targets.

Comparisons with oracle/smac/mmac-paper/nrc run those modes too (each run ≈ 0.1–0.3 s).
"""

from __future__ import annotations

import math
from functools import cache

import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.bench.control import UNSEEN
from ehpss_hil.physics.load import load_params
from ehpss_hil.report.metrics import RunMetrics, compute_metrics
from ehpss_hil.scenario import load_scenario
from ehpss_hil.sim import run_scenario

PARAMS = load_params()
UM = 1e-6


@cache
def metrics(name: str, mode: str) -> RunMetrics:
    sub = "extra/" if name.startswith(("unseen", "kq")) else ""
    sc = load_scenario(PROJECT_ROOT / "scenarios" / f"{sub}{name}.yaml")
    return compute_metrics(run_scenario(sc, mode, PARAMS))


def _events_ok(name: str) -> None:
    mm, orc = metrics(name, "mmac"), metrics(name, "oracle")
    for em, eo in zip(mm.events, orc.events, strict=True):
        assert em.switches <= 10
        if math.isfinite(eo.recovery_s):
            assert em.recovery_s <= 0.02, f"{name} @ {em.t_s}"


def test_fault_free() -> None:
    assert metrics("fault-free", "mmac").rms_error_m <= 3 * UM
    assert metrics("fault-free", "mmac").switches == 0


@pytest.mark.parametrize("name", ["case1-loe", "case3-combined"])
def test_case1_case3_close_to_oracle(name: str) -> None:
    assert metrics(name, "mmac").rms_error_m <= metrics(name, "oracle").rms_error_m + 5 * UM
    best = min(metrics(name, "smac").rms_error_m, metrics(name, "mmac-paper").rms_error_m)
    assert metrics(name, "mmac").rms_error_m <= best + 2 * UM
    _events_ok(name)


def test_case2_drift_and_sensor_failure() -> None:
    m = metrics("case2-drift", "mmac")
    assert m.rms_error_m <= 10 * UM
    assert m.events[-1].peak_error_m <= 10 * UM  # the failure (k_DFT = 0) at 3.5 s
    active = m.events[-1].active_model
    assert active is not None and active["spool"] == 0
    assert active["position"] in (6, 7, 8)  # a θ_D ≈ 0 model
    for other in ("smac", "mmac-paper"):
        assert metrics("case2-drift", other).rms_error_m >= 2 * m.rms_error_m
    _events_ok("case2-drift")


def test_case4_disturbance() -> None:
    m = metrics("case4-disturbance", "mmac")
    assert m.rms_error_m <= 100 * UM
    assert m.rms_error_m < metrics("case4-disturbance", "nrc").rms_error_m
    _events_ok("case4-disturbance")


@pytest.mark.parametrize(
    "name",
    UNSEEN,
)
def test_unseen_faults(name: str) -> None:
    assert metrics(name, "mmac").rms_error_m <= 20 * UM


def test_flow_gain_loss_no_worse_than_nrc() -> None:
    m = metrics("kq-loss", "mmac")
    assert m.rms_error_m <= metrics("kq-loss", "nrc").rms_error_m
    assert max(e.switches for e in m.events) <= 10
