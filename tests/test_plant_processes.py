"""``ehpss-hil run --lockstep`` with a scenario's own plant (real processes on the embedded bus, in
a private network namespace): the emulator process builds the scenario's nonlinear plant, so the
controller's commands are the offline simulation's bit for bit. No timing is asserted."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from _proc import lockstep_plan
from _scenarios import short_scenario_yaml

from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.orchestrate import check_exit_codes, execute
from ehpss_hil.physics.plantspec import PlantSpec
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.scenario import load_scenario
from ehpss_hil.sim.lockstep import run_scenario

NETNS_SKIP = netns_unavailable_reason()
pytestmark = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")

PLANT = "plant: {model: nonlinear, area_ratio: 0.6, coulomb_friction_n: 50.0, flow_gain_1_s3: 1.1341e8}\n"


def test_lockstep_run_with_the_scenarios_nonlinear_plant(tmp_path: Path) -> None:
    scenario = tmp_path / "nl.yaml"
    scenario.write_text(short_scenario_yaml("short-nl", 0.5, "{t_s: 0.3, k_loe: 0.6}") + PLANT)
    sc = load_scenario(scenario)
    assert sc.plant.model == "nonlinear"
    out = tmp_path / "lockstep"
    check_exit_codes(execute(lockstep_plan(scenario, out, "nrc")))
    sim = run_scenario(sc, "nrc")
    cmd = load_log_run(out / "bus.log").commanded_current_a
    n = len(sim.current_a) - 1
    assert len(cmd) >= n
    assert np.array_equal(cmd[:n], sim.current_a[1 : n + 1])
    # and the nominal linear plant would have given other commands
    nominal = run_scenario(replace(sc, plant=PlantSpec()), "nrc")
    assert not np.array_equal(cmd[:n], nominal.current_a[1 : n + 1])
