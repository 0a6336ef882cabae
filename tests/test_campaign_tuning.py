"""A campaign file sets the controller's tuning for every run (``tuning:``, validated like a
controller config's), the runs use it, and summary.md says which keys differ from the defaults."""

from __future__ import annotations

from pathlib import Path

import pytest
from _proc import ROOT

from ehpss_hil.campaign.runs import RunTask, execute
from ehpss_hil.campaign.sampling import plan_runs
from ehpss_hil.campaign.session import run_campaign
from ehpss_hil.campaign.spec import load_campaign
from ehpss_hil.errors import ConfigError

FILE = """\
name: tuned
base: {base}
samples: 2
seed: 4
duration_s: 1.0
faults:
  count: [1, 1]
  onset_s: [0.0, 0.0]
  kinds: {{drift: {{magnitude: [0.8, 0.8]}}}}
"""


def _write(tmp_path: Path, extra: str) -> Path:
    p = tmp_path / "tuned.yaml"
    p.write_text(FILE.format(base=ROOT / "scenarios" / "case1-loe.yaml") + extra)
    return p


def test_the_tuning_reaches_every_run_and_the_summary(tmp_path: Path) -> None:
    """A drift of 0.8 present at power-on on the nominal plant: with the default pressure-gain
    uncertainty (±20 %) it is the plant's flow gain as much as the sensor's and is left to the
    plain loop; a commissioned controller (0) attributes it to the sensor and compensates it."""
    camp = load_campaign(_write(tmp_path, "tuning: {pressure_gain_uncertainty: 0.0}\n"))
    assert camp.spec.tuning.pressure_gain_uncertainty == 0.0
    plan = plan_runs(camp)[0]
    task = RunTask(plan.index, plan.run_hash, plan.scenario, ("nrc", "mmac"), "quantize", camp.spec.tuning)
    commissioned = execute(task)["metrics"]
    default = execute(RunTask(plan.index, plan.run_hash, plan.scenario, ("nrc", "mmac")))["metrics"]
    nrc = commissioned["nrc.rms_error_m"]
    assert default["nrc.rms_error_m"] == nrc
    assert commissioned["mmac.rms_error_m"] < 0.2 * nrc
    assert default["mmac.rms_error_m"] > 0.5 * nrc
    out = tmp_path / "out"
    run_campaign(camp, out, workers=1, figures=False)
    assert "- controller tuning: pressure_gain_uncertainty 0.0" in (out / "summary.md").read_text()


def test_an_unknown_or_out_of_range_tuning_key_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"tuning\.pressure_gain_uncertaintyy: unknown key"):
        load_campaign(_write(tmp_path, "tuning: {pressure_gain_uncertaintyy: 0.0}\n"))
    with pytest.raises(ConfigError, match=r"tuning\.pressure_gain_uncertainty\b"):
        load_campaign(_write(tmp_path, "tuning: {pressure_gain_uncertainty: 0.9}\n"))
