"""A scenario's ``plant:`` section: the emulated plant's own parameters (plant ≠ model)."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.errors import ConfigError
from ehpss_hil.physics.hydraulics import NonlinearPlant
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import LinearPlant
from ehpss_hil.physics.plantspec import PlantSpec
from ehpss_hil.report.metrics import compute_metrics
from ehpss_hil.scenario import Scenario, load_scenario
from ehpss_hil.sim.lockstep import run_scenario

PARAMS = load_params()
NOMINAL_FLOW_GAIN = PARAMS.plant.flow_gain_1_s3

BASE = """\
name: p
duration_s: 1.0
reference: {kind: sine, amplitude_m: 0.001, omega_rad_s: 5.0}
"""


def _load(tmp_path: Path, text: str) -> Scenario:
    p = tmp_path / "s.yaml"
    p.write_text(text)
    return load_scenario(p)


def test_plant_section_builds_the_emulated_plant_only(tmp_path: Path) -> None:
    sc = _load(tmp_path, BASE + f"plant: {{flow_gain_1_s3: {1.1 * NOMINAL_FLOW_GAIN!r}}}\n")
    emu = PlantEmulation(PARAMS, sc)
    assert isinstance(emu.plant, LinearPlant)
    assert emu.plant.plant_params.flow_gain_1_s3 == pytest.approx(1.1 * NOMINAL_FLOW_GAIN)
    assert emu.plant.plant_params.load_mass_kg == PARAMS.plant.load_mass_kg
    assert emu.params is PARAMS  # the controller's params are untouched


@pytest.mark.parametrize("mode", ["nrc", "oracle"])
def test_flow_gain_off_the_model_moves_rms_and_keeps_the_models(tmp_path: Path, mode: str) -> None:
    sc = _load(tmp_path, BASE)
    off = replace(sc, plant=PlantSpec(flow_gain_1_s3=1.1 * NOMINAL_FLOW_GAIN))
    a, b = run_scenario(sc, mode, PARAMS), run_scenario(off, mode, PARAMS)
    np.testing.assert_array_equal(a.y_m_m, b.y_m_m)  # y_m: the controller's params
    ra, rb = compute_metrics(a).rms_error_m, compute_metrics(b).rms_error_m
    assert abs(rb - ra) > 0.05 * ra, (ra, rb)
    # a faster plant (K_c 10 % up) leads y_m: x − y_m changes sign against the nominal's lag
    assert not np.allclose(a.x_true_m, b.x_true_m)


def test_plant_params_argument_is_the_base_of_the_section(tmp_path: Path) -> None:
    sc = _load(tmp_path, BASE + "plant: {load_mass_kg: 25.0}\n")
    other = replace(PARAMS.plant, flow_gain_1_s3=2.0 * NOMINAL_FLOW_GAIN)
    emu = PlantEmulation(PARAMS, sc, other)
    assert isinstance(emu.plant, LinearPlant)
    assert emu.plant.plant_params.flow_gain_1_s3 == 2.0 * NOMINAL_FLOW_GAIN
    assert emu.plant.plant_params.load_mass_kg == 25.0


def test_nonlinear_model_selected(tmp_path: Path) -> None:
    sc = _load(tmp_path, BASE + "plant: {model: nonlinear, area_ratio: 0.6, supply_pressure_pa: 2.0e7}\n")
    emu = PlantEmulation(PARAMS, sc)
    assert isinstance(emu.plant, NonlinearPlant)
    assert emu.plant.hp.area_b_m2 == pytest.approx(0.6 * PARAMS.plant.piston_area_m2)
    assert emu.plant.hp.supply_pressure_pa == 2.0e7


@pytest.mark.parametrize(
    "section,key_path,reason",
    [
        ("{flow_gain: 1.0e8}", "plant.flow_gain", "unknown key"),
        ("{flow_gain_1_s3: -1.0}", "plant.flow_gain_1_s3", "expected a value >"),
        ("{area_ratio: 0.5}", "plant.area_ratio", "needs model: nonlinear"),
        ("{model: nonlinear, area_ratio: 1.5}", "plant.area_ratio", "<= 1.0"),
        ("{model: quadratic}", "plant.model", "one of"),
        (
            "{model: nonlinear, supply_pressure_pa: 1.0e6, return_pressure_pa: 2.0e6}",
            "plant.return_pressure_pa",
            "below the supply",
        ),
        (
            "{model: nonlinear, return_pressure_pa: 9.0e6, supply_pressure_pa: 1.0e5}",
            "plant.return_pressure_pa",
            "below the supply",
        ),
        (
            "{model: nonlinear, supply_pressure_pa: 1.0e5, return_pressure_pa: 1.0e5}",
            "plant.return_pressure_pa",
            "below the supply",
        ),
        ("{model: nonlinear, spool_overlap_m: 0.01}", "plant.spool_overlap_m", "below the spool stroke"),
        ("{spool_stroke_m: 0.02}", "plant.spool_stroke_m", "<= 0.01"),
        ("[1, 2]", "plant", "expected a mapping"),
    ],
)
def test_bad_plant_section_names_key_path(tmp_path: Path, section: str, key_path: str, reason: str) -> None:
    with pytest.raises(ConfigError) as exc:
        _load(tmp_path, BASE + f"plant: {section}\n")
    assert exc.value.key_path == key_path
    assert reason in exc.value.reason


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ehpss_hil.cli", *args], capture_output=True, text=True, check=False
    )


def test_sim_params_sets_the_controllers_model_only(tmp_path: Path) -> None:
    """``sim --params FILE``: the controller (its models, y_m) uses FILE, the plant stays
    configs/params.yaml (a model 10 % off a nominal plant moves the RMS); a missing FILE is
    one line and exit 2."""
    sc = tmp_path / "s.yaml"
    sc.write_text(BASE.replace("duration_s: 1.0", "duration_s: 0.5"))
    text = (PROJECT_ROOT / "configs" / "params.yaml").read_text()
    off = tmp_path / "params.yaml"
    off.write_text(text.replace("flow_gain_1_s3: 1.031e8", "flow_gain_1_s3: 1.1341e8"))
    assert off.read_text() != text
    rows: list[float] = []
    for extra in ([], ["--params", str(off)]):
        out = tmp_path / f"r{len(rows)}.json"
        res = _cli("sim", str(sc), "-C", "oracle", "-j", "1", "--json", str(out), *extra)
        assert res.returncode == 0, res.stderr
        rows.append(json.loads(out.read_text())[0]["rms_error_m"])
    direct = compute_metrics(
        run_scenario(load_scenario(sc), "oracle", load_params(off), plant_params=PARAMS.plant)
    )
    assert rows[1] == pytest.approx(direct.rms_error_m, rel=1e-9)
    assert abs(rows[1] - rows[0]) > 0.05 * rows[0]
    bad = _cli("sim", str(sc), "-C", "nrc", "-j", "1", "--params", str(tmp_path / "missing.yaml"))
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_sim_says_whether_plant_equals_model() -> None:
    from ehpss_hil.commands.sim import plant_line

    nominal = str(PROJECT_ROOT / "scenarios" / "fault-free.yaml")
    rod = str(PROJECT_ROOT / "scenarios" / "plant" / "nonlinear-single-rod.yaml")
    assert plant_line([nominal], "", False).startswith("plant = model")
    line = plant_line([nominal, rod], "", False)
    assert (
        line.startswith("plant ≠ model") and "plant-nonlinear-single-rod: nonlinear, area_ratio 0.6" in line
    )
    assert "fault-free" not in line
    assert plant_line([nominal], "mine.yaml", True).startswith("plant ≠ model (controller params mine.yaml")


def test_check_config_builds_the_plant(tmp_path: Path) -> None:
    """A plant the schema accepts but whose mapping fails (B_v/m above the damping): check-config
    builds it, one line naming the key, exit 2; a good one is summarized with its plant."""
    bad = tmp_path / "bad.yaml"
    bad.write_text(BASE + "plant: {model: nonlinear, viscous_friction_n_s_m: 1.0e6}\n")
    res = _cli("check-config", str(bad))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "plant.viscous_friction_n_s_m" in res.stderr and "cylinder_damping" in res.stderr
    good = tmp_path / "good.yaml"
    good.write_text(BASE + "plant: {model: nonlinear, area_ratio: 0.6}\n")
    res = _cli("check-config", str(good))
    assert res.returncode == 0, res.stderr
    assert "plant nonlinear, area_ratio 0.6" in res.stdout


def test_a_bad_plant_in_a_worker_process_is_one_line_exit_2(tmp_path: Path) -> None:
    """The error crosses the process pool (ConfigError pickles with its fields) and names the
    file: no hang, no traceback."""
    import pickle

    err = pickle.loads(pickle.dumps(ConfigError("f.yaml", "plant.area_ratio", "bad")))
    assert (err.source, err.key_path, err.reason, str(err)) == (
        "f.yaml",
        "plant.area_ratio",
        "bad",
        "f.yaml: plant.area_ratio: bad",
    )
    bad = tmp_path / "bad.yaml"
    bad.write_text(BASE + "plant: {model: nonlinear, viscous_friction_n_s_m: 1.0e6}\n")
    good = PROJECT_ROOT / "scenarios" / "fault-free.yaml"
    res = subprocess.run(
        [sys.executable, "-m", "ehpss_hil.cli", "sim", str(bad), str(good), "-C", "nrc", "-j", "2"],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,  # a hang guard only
    )
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [
        f"ehpss-hil sim: error: {bad}: plant.viscous_friction_n_s_m: B_v/m must stay below "
        "cylinder_damping (2576 1/s)"
    ]
