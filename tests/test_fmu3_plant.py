"""``plant: {model: fmu}`` with an FMI 3.0 FMU: the same test plant as tests/test_fmu_plant.py
built by pythonfmu3 (``Float64`` variables, ``fmi3DoStep``) and run by fmpy's FMU3Slave — lockstep
equivalence with the built-in plant on the paper's cases, sub-steps from FMI 3.0's
``fixedInternalStepSize``, the unit check on ``Float64``, and the hostile FMUs specific to FMI
3.0: a step that returns fmi3OK but asks to terminate, and a step that returns fmi3Discard (one
line each, never a traceback)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu3")

from _fmu import cli, scenario
from _proc import EHPSS_HIL, ROOT

from ehpss_hil.bench.fmu import equivalence, fmu_spec
from ehpss_hil.physics.fmuplant import FmuPlant
from ehpss_hil.physics.fmutest import TEST_FMU_MAP, UNITS, build_test_fmu
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import make_plant
from ehpss_hil.physics.plantspec import PlantSpec
from ehpss_hil.scenario import load_scenario


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The FMI 3.0 test FMU and its hostile variants."""
    d = tmp_path_factory.mktemp("fmus3")
    return {
        "good": build_test_fmu(d, fmi_version=3),
        "fail_1s": build_test_fmu(d, fmi_version=3, fail_at_s=1.0),
        "term_1s": build_test_fmu(d, fmi_version=3, terminate_at_s=1.0),
        "mm": build_test_fmu(d / "mm", fmi_version=3, units={**UNITS, "position_m": "mm"}),
        "fixed_500us": build_test_fmu(d, fmi_version=3, fixed_step_s=5e-4),
    }


def test_the_fixture_is_an_fmi3_fmu_run_through_fmi3_calls(fmus: dict[str, Path]) -> None:
    """The FMU is FMI 3.0 (so the plant takes the FMU3Slave path) and steps the plant."""
    plant = make_plant(fmu_spec(fmus["good"], TEST_FMU_MAP), load_params().plant, 1e-3)
    assert isinstance(plant, FmuPlant)
    assert plant.desc.fmi_major == 3  # the plant picks FMU3Slave and the fmi3 calls by this
    for _ in range(100):
        assert plant.step(0.01) == 0.01
    assert plant.position_m > 1e-5 and plant.coil_current_a == 0.01  # moved; the echo output
    plant.close()


@pytest.mark.parametrize(("case", "mode"), [("case1-loe", "nrc"), ("case3-combined", "mmac")])
def test_sim_with_the_fmi3_fmu_matches_the_builtin_plant(fmus: dict[str, Path], case: str, mode: str) -> None:
    """Lockstep, the paper's case: the FMI 3.0 FMU gives the piston path and the tracking RMS
    error of ``plant: {model: nonlinear}`` within 1 % (the faults reach it through its
    k_loe/k_q inputs: case 1 with nrc tracks far worse than fault-free)."""
    sc = load_scenario(ROOT / "scenarios" / f"{case}.yaml")
    e = equivalence(sc, fmu_spec(fmus["good"], TEST_FMU_MAP), mode)
    assert e.position_diff <= 0.01 and e.rms_diff <= 0.01, e
    if case == "case1-loe":
        assert e.rms_fmu_m > 10e-6  # LOE 80 % uncompensated: tens of µm (fault-free: ~4 µm)


def test_a_fixed_internal_step_is_taken_in_sub_steps(fmus: dict[str, Path]) -> None:
    """FMI 3.0's ``fixedInternalStepSize`` (0.5 ms, before the default experiment's 1 ms): two
    sub-steps per 1 ms sample, matching the built-in plant at 1 ms (the same 8 integration
    sub-steps of 125 µs over the sample); the FMU without it takes one step per sample."""
    prm = load_params().plant
    plain = make_plant(fmu_spec(fmus["good"], TEST_FMU_MAP), prm, 1e-3)
    assert isinstance(plain, FmuPlant) and plain.substeps == 1
    plain.close()
    fmu = make_plant(fmu_spec(fmus["fixed_500us"], TEST_FMU_MAP), prm, 1e-3)
    ref = make_plant(PlantSpec(model="nonlinear"), prm, 1e-3)
    assert isinstance(fmu, FmuPlant) and fmu.substeps == 2
    for k in range(500):
        i = 2e-5 * math.sin(2.0 * math.pi * 5.0 * k * 1e-3)
        assert fmu.step(i) == ref.step(i)
    assert ref.position_m != 0.0
    assert fmu.position_m == pytest.approx(ref.position_m, rel=1e-9)
    assert fmu.load_pressure_pa == pytest.approx(ref.load_pressure_pa, rel=1e-9)
    fmu.close()


def test_a_float64_unit_mismatch_is_refused(fmus: dict[str, Path], tmp_path: Path) -> None:
    proc = cli([*EHPSS_HIL, "check-config", str(scenario(tmp_path, fmus["mm"]))], tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "plant.fmu_map.position_m: 'position_m' in ehpss_axis3.fmu is in 'mm', the bench needs 'm'" in (
        proc.stderr
    )


@pytest.mark.parametrize(
    ("kind", "expected"),
    [
        ("term_1s", "FMU ehpss_axis3_term_1000ms.fmu: asked to terminate at t = 1.0000 s"),
        ("fail_1s", "FMU ehpss_axis3_fail_1000ms.fmu: fmi3DoStep returned Discard (step at t = 1.0000 s)"),
    ],
)
def test_an_fmi3_step_failure_is_one_line_in_sim(
    fmus: dict[str, Path], tmp_path: Path, kind: str, expected: str
) -> None:
    """The FMU loads (check-config passes) and fails at t = 1 s: ``sim`` stops with one line and
    exit 1 — for terminateSimulation even though fmi3DoStep itself returned OK."""
    sc = scenario(tmp_path, fmus[kind])
    assert cli([*EHPSS_HIL, "check-config", str(sc)], tmp_path).returncode == 0
    proc = cli([*EHPSS_HIL, "sim", str(sc), "-C", "mmac"], tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.count("\n") == 1 and expected in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stdout
