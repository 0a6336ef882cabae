"""The evidence layer (control/evidence/): one update per fresh sample, one record, the decision
applied through the one owner of the estimates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ehpss_hil.control.adaptive import MmacController
from ehpss_hil.control.base import Measurement
from ehpss_hil.control.evidence import Hypothesis
from ehpss_hil.control.registry import make_controller
from ehpss_hil.physics.faults import FaultState
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import PlantStepper

PARAMS = load_params()
TS = 1e-3


def _closed_loop(fault: FaultState, n: int = 3000) -> tuple[MmacController, list[Hypothesis], int]:
    """mmac on the linear plant tracking the paper's 1 mm, 5 rad/s sine, ``fault`` from 0.5 s,
    1 µm of position noise and 10 kPa of pressure noise. Returns the controller, the record's
    hypothesis per sample and how many distinct record objects the layer returned."""
    plant = PlantStepper(PARAMS, TS)
    c = make_controller("mmac", PARAMS, TS)
    assert isinstance(c, MmacController)
    m = Measurement()
    rng = np.random.default_rng(1)
    f = FaultState()
    hyp: list[Hypothesis] = []
    records = set()
    for k in range(n):
        if k == 500:
            f = fault
            plant.set_faults(f)
        m.position_m = f.k_dft * plant.position_m + 1e-6 * rng.standard_normal()
        m.spool_m = plant.spool_actual_m
        m.coil_current_a = plant.coil_current_a
        m.load_pressure_pa = plant.load_pressure_pa + 1e4 * rng.standard_normal()
        m.reference_m = 1e-3 * math.sin(5.0 * k * TS)
        plant.step(c.step(m).current_a)
        hyp.append(c.evidence.record.hypothesis)
        records.add(id(c.evidence.record))
    return c, hyp, len(records)


def test_a_flow_gain_loss_is_attributed_to_the_flow_gain() -> None:
    c, hyp, n_records = _closed_loop(FaultState(k_q=0.7))
    assert hyp[400] is Hypothesis.NONE  # before the fault nothing is attributed
    assert hyp[-1] is Hypothesis.FLOW and all(h is Hypothesis.FLOW for h in hyp[-500:])
    assert c.evidence.record.k_q == c.est.k_q == c.k_q_hat == pytest.approx(0.7, abs=0.03)
    assert c.k_dft_hat == 1.0  # the sensor is taken as healthy under H_Q
    assert n_records == 1  # one record, rewritten: nothing allocated per sample


def test_a_sensor_drift_is_attributed_to_the_sensor() -> None:
    c, hyp, _ = _closed_loop(FaultState(k_dft=0.7))
    assert hyp[-1] is Hypothesis.SENSOR and Hypothesis.FLOW not in hyp
    assert c.est.k_dft == c.k_dft_hat == pytest.approx(0.7, abs=0.01) and c.k_q_hat == 1.0
    assert not c.evidence.record.position_nominal  # the drift is compensated


def test_nothing_is_attributed_on_a_healthy_plant() -> None:
    c, hyp, _ = _closed_loop(FaultState())
    assert set(hyp) == {Hypothesis.NONE}
    assert not c.evidence.record.fallback and c.fallback_count() == 0
