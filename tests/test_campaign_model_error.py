"""Campaign files sample model error (plant ≠ model): a relative range per plant key, drawn per
run into the scenario's ``plant:`` section, reported in the table and in summary.md."""

from __future__ import annotations

import math
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from _proc import ROOT

from ehpss_hil.campaign.sampling import plan_runs
from ehpss_hil.campaign.scenario_file import scenario_data
from ehpss_hil.campaign.session import run_campaign
from ehpss_hil.campaign.spec import load_campaign
from ehpss_hil.campaign.table import PARQUET_NAME
from ehpss_hil.errors import ConfigError
from ehpss_hil.physics.load import load_params
from ehpss_hil.report.metrics import compute_metrics
from ehpss_hil.scenario import load_scenario
from ehpss_hil.sim.lockstep import run_scenario

FILE = """\
name: me
base: {base}
samples: {samples}
sampler: sobol
seed: 2
duration_s: 0.6
faults:
  count: [1, 1]
  onset_s: [0.1, 0.3]
  kinds: {{loe: {{magnitude: [0.4, 0.8]}}, drift: {{}}}}
"""
MODEL_ERROR = """\
model_error:
  flow_gain_1_s3: [-0.2, 0.2]
  load_mass_kg: [0.0, 0.5]
"""
NOMINAL = load_params().plant


def _write(tmp_path: Path, extra: str = MODEL_ERROR, samples: int = 16) -> Path:
    p = tmp_path / "me.yaml"
    p.write_text(FILE.format(base=ROOT / "scenarios" / "case1-loe.yaml", samples=samples) + extra)
    return p


def test_each_run_gets_its_own_plant_within_the_ranges(tmp_path: Path) -> None:
    plans = plan_runs(load_campaign(_write(tmp_path)))
    gains = []
    for p in plans:
        errors = dict(p.model_error)
        assert set(errors) == {"flow_gain_1_s3", "load_mass_kg"}
        assert -0.2 <= errors["flow_gain_1_s3"] <= 0.2 and 0.0 <= errors["load_mass_kg"] <= 0.5
        plant = p.scenario.plant
        assert plant.flow_gain_1_s3 == pytest.approx(NOMINAL.flow_gain_1_s3 * (1 + errors["flow_gain_1_s3"]))
        assert plant.load_mass_kg == pytest.approx(NOMINAL.load_mass_kg * (1 + errors["load_mass_kg"]))
        row = p.parameters()
        assert row["model_error.flow_gain_1_s3"] == errors["flow_gain_1_s3"]
        gains.append(errors["flow_gain_1_s3"])
    assert min(gains) < -0.1 and max(gains) > 0.1  # the sampler spreads them over the range
    again = plan_runs(load_campaign(_write(tmp_path)))
    assert [p.run_hash for p in again] == [p.run_hash for p in plans]


def test_without_model_error_runs_and_hashes_are_as_before(tmp_path: Path) -> None:
    """No plant section is written for a nominal plant: a campaign without model_error draws the
    same scenarios (and run hashes) as before scenarios had one."""
    plans = plan_runs(load_campaign(_write(tmp_path, extra="")))
    assert all(p.model_error == () and "plant" not in scenario_data(p.scenario) for p in plans)
    assert all(not any(k.startswith("model_error.") for k in p.parameters()) for p in plans)


def test_nonlinear_model_and_bad_ranges(tmp_path: Path) -> None:
    plans = plan_runs(load_campaign(_write(tmp_path, MODEL_ERROR + "  model: nonlinear\n", samples=4)))
    assert all(p.scenario.plant.model == "nonlinear" for p in plans)
    with pytest.raises(ConfigError) as exc:
        load_campaign(_write(tmp_path, "model_error: {flow_gain_1_s3: [0.2, -0.2]}\n"))
    assert exc.value.key_path == "model_error.flow_gain_1_s3"
    with pytest.raises(ConfigError) as exc:
        load_campaign(_write(tmp_path, "model_error: {flow_gain: [-0.2, 0.2]}\n"))
    assert exc.value.key_path == "model_error.flow_gain" and "unknown key" in exc.value.reason
    with pytest.raises(ConfigError) as exc:
        load_campaign(_write(tmp_path, "model_error: {load_mass_kg: [-0.95, 0.0]}\n"))
    assert exc.value.key_path == "model_error.load_mass_kg[0]"


def test_campaign_reports_model_error_and_worst_runs_rerun_exactly(tmp_path: Path) -> None:
    camp = load_campaign(_write(tmp_path, samples=8))
    out = tmp_path / "out"
    res = run_campaign(camp, out, workers=1, figures=False)
    table = pq.read_table(out / PARQUET_NAME).to_pylist()
    assert len(table) == 8
    assert all(math.isfinite(r["model_error.flow_gain_1_s3"]) for r in table)
    md = (out / "summary.md").read_text()
    assert "## Model error" in md and "| flow_gain_1_s3 | -20 … +20 |" in md
    assert "model error (plant ≠ model" in md
    worst = res.summaries[-1].worst_gap[0]
    sc = load_scenario(worst.paths["gap"])
    assert sc.plant.flow_gain_1_s3 is not None
    rerun = compute_metrics(run_scenario(sc, "mmac", load_params())).rms_error_m
    assert rerun == worst.rms_m["mmac"]
