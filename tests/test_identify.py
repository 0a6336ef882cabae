"""``ehpss-hil identify`` in lockstep: real experiments against the emulated plant of a
scenario's ``plant:`` section, the least-squares fit, the params file and the limits."""

from __future__ import annotations

import dataclasses
import subprocess
from pathlib import Path

import pytest
from _proc import EHPSS_HIL, ENV, ROOT

from ehpss_hil.identify.engine import Identification, identify_lockstep
from ehpss_hil.identify.paramsfile import write_params
from ehpss_hil.identify.report import truth_of
from ehpss_hil.physics.load import load_params
from ehpss_hil.scenario import load_scenario

#: flow gain +20 % (K_c), hydraulic natural frequency −20 %: the plant the issue names
MISMATCHED = ROOT / "scenarios" / "identify" / "kq120-wh080.yaml"
#: the issue's tolerances: gains and natural frequencies within 5 %, dampings within 25 %
GAINS_AND_FREQUENCIES = (
    "flow_gain_1_s3",
    "valve_gain_m_per_a_s2",
    "velocity_gain_1_s",
    "valve_static_gain_m_per_a",
    "omega_sv_rad_s",
    "omega_h_rad_s",
)
DAMPINGS = ("zeta_sv", "zeta_h")


@pytest.fixture(scope="module")
def identified() -> Identification:
    return identify_lockstep(load_scenario(MISMATCHED), load_params())


def test_identify_recovers_the_mismatched_plant_within_the_issue_tolerances(
    identified: Identification,
) -> None:
    res, truth = identified.result, identified.truth
    assert truth is not None
    nominal = load_params().plant
    assert truth.flow_gain_1_s3 != nominal.flow_gain_1_s3  # the plant really is not the start model
    for name in GAINS_AND_FREQUENCIES:
        err = res.estimate(name).value / truth_of(truth, name) - 1.0
        assert abs(err) <= 0.05, (name, err)
    for name in DAMPINGS:
        err = res.estimate(name).value / truth_of(truth, name) - 1.0
        assert abs(err) <= 0.25, (name, err)
    # the start model's ω_h is 25 % above the plant's: the fit moved, and says how sure it is
    assert abs(res.estimate("omega_h_rad_s").value / nominal.hydraulic_stiffness_1_s2**0.5 - 0.8) < 0.04
    for e in res.keys:
        assert 0.0 < e.rel_ci95 < 0.05, e


def test_the_params_file_round_trips_through_load_params(identified: Identification, tmp_path: Path) -> None:
    out = tmp_path / "P.yaml"
    write_params(out, identified.result, str(MISMATCHED))
    loaded = load_params(out)
    assert loaded == identified.result.params
    for f in dataclasses.fields(loaded.plant):
        assert getattr(loaded.plant, f.name) == getattr(identified.result.params.plant, f.name)


def _cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*EHPSS_HIL, *args], cwd=cwd, env=ENV, capture_output=True, text=True, timeout=600, check=False
    )


def test_the_command_writes_a_params_file_and_report_that_sim_uses(tmp_path: Path) -> None:
    out, rep = tmp_path / "P.yaml", tmp_path / "rep"
    r = _cli("identify", "--scenario", str(MISMATCHED), "--out", str(out), "--report", str(rep))
    assert r.returncode == 0, r.stderr
    assert "omega_h_rad_s" in r.stdout
    assert load_params(out).plant.flow_gain_1_s3 == pytest.approx(7.91808e7, rel=0.05)
    assert "omega_h_rad_s" in (rep / "report.md").read_text()
    rows = (rep / "frf.csv").read_text().splitlines()
    assert rows[0].startswith("f_hz,") and len(rows) > 30
    s = _cli("sim", str(MISMATCHED), "--params", str(out), "-C", "nrc", "-j", "1")
    assert s.returncode == 0, s.stderr
    assert f"controller params {out}" in s.stdout


def test_a_crossed_travel_limit_is_fail_safe_one_line_and_exit_1(tmp_path: Path) -> None:
    out = tmp_path / "P.yaml"
    r = _cli("identify", "--scenario", str(MISMATCHED), "--out", str(out), "--travel-limit", "1e-5")
    assert r.returncode == 1, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "fail-safe" in lines[0] and "travel" in lines[0], r.stderr
    assert not out.exists()


def test_a_bad_limit_is_one_line_and_exit_2(tmp_path: Path) -> None:
    r = _cli(
        "identify", "--scenario", str(MISMATCHED), "--out", str(tmp_path / "P.yaml"), "--amplitude", "-1"
    )
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "amplitude_m" in r.stderr


def test_bench_identify_judges_a_plant_and_mmac_with_its_identified_params(tmp_path: Path) -> None:
    out = tmp_path / "b.json"
    r = _cli("bench", "identify", "--plant", "wv130", "--json", str(out))
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "bench identify: 9 target(s) PASS" in r.stdout
    import json

    data = json.loads(out.read_text())
    omega = next(row for row in data["identification"] if row["quantity"] == "omega_sv_rad_s")
    assert omega["true"] == pytest.approx(9.97945e6**0.5)
    assert abs(omega["identified"] / omega["true"] - 1) < 0.05
    assert {row["run"] for row in data["control"]} == {"fault-free", "loe", "drift"}
