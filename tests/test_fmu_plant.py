"""``plant: {model: fmu}``: the test FMU (pythonfmu around our own nonlinear plant, built here
into a temporary folder) run by fmpy behind the Plant protocol — lockstep equivalence with the
built-in plant, sub-steps, the map's checks at check-config, faults around the FMU, and hostile
FMUs (one line each, never a traceback)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from _fmu import cli as _cli
from _fmu import scenario as _scenario
from _proc import EHPSS_HIL, FIRMWARE_SIM, ROOT

from ehpss_hil.bench.fmu import equivalence, fmu_spec
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.errors import InjectError
from ehpss_hil.physics.fmuplant import FmuPlant
from ehpss_hil.physics.fmutest import TEST_FMU_MAP, UNITS, build_test_fmu
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import make_plant
from ehpss_hil.physics.plantspec import PlantSpec
from ehpss_hil.scenario import Scenario, load_scenario

EMU_CFG = str(ROOT / "configs" / "emulator.yaml")


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The test FMU and its hostile variants."""
    d = tmp_path_factory.mktemp("fmus")
    good = build_test_fmu(d)
    out = {
        "good": good,
        "fail_1s": build_test_fmu(d, fail_at_s=1.0),
        "mm": build_test_fmu(d / "mm", units={**UNITS, "position_m": "mm"}),
        "not_fmu": d / "notes.fmu",
        "no_binary": d / "no-binary.fmu",
        "not_zip": d / "garbage.fmu",
        "bad_binary": d / "bad-binary.fmu",
    }
    with zipfile.ZipFile(out["not_fmu"], "w") as zf:
        zf.writestr("readme.txt", "a zip, but no FMU")
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(out["no_binary"], "w") as zf:
        for name in src.namelist():
            if not name.startswith("binaries/linux64/"):
                zf.writestr(name, src.read(name))
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(out["bad_binary"], "w") as zf:
        for name in src.namelist():
            zf.writestr(
                name, b"not a shared library" if name.startswith("binaries/linux64/") else src.read(name)
            )
    out["not_zip"].write_bytes(b"\x7fELF not a zip at all")
    return out


# ---- equivalence --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("case", "mode"), [("case1-loe", "nrc"), ("case2-drift", "mmac"), ("case3-combined", "mmac-paper")]
)
def test_sim_with_the_fmu_matches_the_builtin_plant(fmus: dict[str, Path], case: str, mode: str) -> None:
    """Lockstep, the paper's case: the FMU built from our nonlinear plant gives the piston path
    and the tracking RMS error of ``plant: {model: nonlinear}`` within 1 % (the faults reach
    the FMU through its k_loe/k_q inputs: case 1 with nrc tracks far worse than fault-free)."""
    sc = load_scenario(ROOT / "scenarios" / f"{case}.yaml")
    e = equivalence(sc, fmu_spec(fmus["good"], TEST_FMU_MAP), mode)
    assert e.position_diff <= 0.01 and e.rms_diff <= 0.01, e
    if case == "case1-loe":
        assert e.rms_fmu_m > 10e-6  # LOE 80 % uncompensated: tens of µm (fault-free: ~4 µm)


def test_a_shorter_fmu_step_is_taken_in_sub_steps(fmus: dict[str, Path]) -> None:
    """At a 2 ms sample the 1 ms FMU is stepped twice per sample, and matches the built-in plant
    at 2 ms (the same 16 integration sub-steps of 125 µs over the sample)."""
    spec = fmu_spec(fmus["good"], TEST_FMU_MAP)
    fmu = make_plant(spec, load_params().plant, 2e-3)
    ref = make_plant(PlantSpec(model="nonlinear"), load_params().plant, 2e-3)
    assert isinstance(fmu, FmuPlant) and fmu.substeps == 2
    for k in range(500):
        i = 2e-5 * math.sin(2.0 * math.pi * 5.0 * k * 2e-3)
        assert fmu.step(i) == ref.step(i)
    assert ref.position_m != 0.0
    assert fmu.position_m == pytest.approx(ref.position_m, rel=1e-9)
    assert fmu.load_pressure_pa == pytest.approx(ref.load_pressure_pa, rel=1e-9)
    # the emulation's one-call read of the outputs is the properties'
    assert fmu.outputs() == (fmu.position_m, fmu.spool_actual_m, fmu.load_pressure_pa, fmu.coil_current_a)


# ---- the map, at check-config ---------------------------------------------------------------------
@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ({"position_m": "x_piston"}, "plant.fmu_map.position_m: no variable 'x_piston' in ehpss_axis.fmu"),
        ({"spool_m": "k_q", "k_q": ""}, "plant.fmu_map.spool_m: 'k_q' in ehpss_axis.fmu has causality input"),
        (
            {"current_a": "current_echo_a", "current_echo_a": ""},
            "plant.fmu_map.current_a: 'current_echo_a' in ehpss_axis.fmu has causality output",
        ),
        ({"k_loe": "position_m", "position_m": "spool_m", "spool_m": ""}, "plant.fmu_map.spool_m: missing"),
    ],
)
def test_check_config_names_the_map_entry(
    fmus: dict[str, Path], tmp_path: Path, change: dict[str, str], expected: str
) -> None:
    fmap = {k: v for k, v in {**TEST_FMU_MAP, **change}.items() if v}
    sc = _scenario(tmp_path, fmus["good"], fmap=fmap, events=[{"t_s": 0.5, "k_dft": 0.9}])
    proc = _cli([*EHPSS_HIL, "check-config", str(sc)], tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and expected in proc.stderr, proc.stderr


def test_a_unit_mismatch_is_refused(fmus: dict[str, Path], tmp_path: Path) -> None:
    proc = _cli([*EHPSS_HIL, "check-config", str(_scenario(tmp_path, fmus["mm"]))], tmp_path)
    assert proc.returncode == 2
    assert "plant.fmu_map.position_m: 'position_m' in ehpss_axis.fmu is in 'mm', the bench needs 'm'" in (
        proc.stderr
    )


def test_an_actuator_fault_the_map_does_not_name_is_refused(fmus: dict[str, Path], tmp_path: Path) -> None:
    """k_loe without ``fmu_map.k_loe``: refused naming the event; a sensor fault (ours, around
    the FMU) is fine with the same map."""
    fmap = {k: v for k, v in TEST_FMU_MAP.items() if k != "k_loe"}
    bad = _scenario(
        tmp_path / "bad", fmus["good"], fmap=fmap, events=[{"t_s": 0.2}, {"t_s": 0.5, "k_loe": 0.5}]
    )
    bad.write_text(bad.read_text().replace("- t_s: 0.2\n", "- {t_s: 0.2, k_dft: 0.9}\n"))
    proc = _cli([*EHPSS_HIL, "check-config", str(bad)], tmp_path)
    assert proc.returncode == 2
    assert "events[1].k_loe: the FMU plant does not model k_loe: map its input as plant.fmu_map.k_loe" in (
        proc.stderr
    )
    ok = _scenario(tmp_path / "ok", fmus["good"], fmap=fmap, events=[{"t_s": 0.5, "k_dft": 0.5}])
    proc = _cli([*EHPSS_HIL, "check-config", str(ok)], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "plant fmu ehpss_axis.fmu" in proc.stdout


def test_sensor_faults_act_around_the_fmu_and_an_unmodelled_inject_is_refused(fmus: dict[str, Path]) -> None:
    fmap = {k: v for k, v in TEST_FMU_MAP.items() if k != "k_q"}
    spec = fmu_spec(fmus["good"], fmap)
    emu = PlantEmulation(load_params(), Scenario(name="inject", duration_s=10.0, plant=spec))
    for _ in range(200):
        emu.measure()
        emu.advance(0.01)
    with pytest.raises(InjectError, match="k_q"):
        emu.inject(k_q=0.5)
    emu.inject(k_dft=0.5, position_bias_m=1e-4)
    y = emu.measure()
    assert y.true_position_m > 1e-4  # the piston moved under the held current
    assert y.position_m == pytest.approx(0.5 * y.true_position_m + 1e-4, abs=1e-9)
    assert y.coil_current_a == 0.01  # the FMU's echo output


# ---- hostile FMUs ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kind", "expected"),
    [
        ("not_fmu", "plant.path: notes.fmu is not an FMU (no modelDescription.xml in the zip)"),
        ("not_zip", "plant.path: garbage.fmu is not an FMU (not a zip archive)"),
        ("no_binary", "plant.path: no-binary.fmu has no binary for linux64 (it has: win64)"),
        (
            "bad_binary",
            "plant.path: FMU bad-binary.fmu: initialization failed: Failed to load shared library",
        ),
    ],
)
def test_a_hostile_fmu_is_one_line_and_exit_2(
    fmus: dict[str, Path], tmp_path: Path, kind: str, expected: str
) -> None:
    sc = _scenario(tmp_path, fmus[kind])
    for argv in ([*EHPSS_HIL, "check-config", str(sc)], [*EHPSS_HIL, "sim", str(sc), "-C", "nrc"]):
        proc = _cli(argv, tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.count("\n") == 1 and expected in proc.stderr, proc.stderr
        assert "Traceback" not in proc.stderr + proc.stdout


def test_a_step_failure_is_one_line_in_sim(fmus: dict[str, Path], tmp_path: Path) -> None:
    sc = _scenario(tmp_path, fmus["fail_1s"])
    assert _cli([*EHPSS_HIL, "check-config", str(sc)], tmp_path).returncode == 0  # it loads
    proc = _cli([*EHPSS_HIL, "sim", str(sc), "-C", "mmac"], tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "FMU ehpss_axis_fail_1000ms.fmu: fmi2DoStep returned Discard (step at t = 1.0000 s)" in proc.stderr
    assert "Traceback" not in proc.stdout


def test_the_emulator_goes_fail_safe_when_the_fmu_step_fails(fmus: dict[str, Path], tmp_path: Path) -> None:
    """firmware-sim (realtime, python-can's virtual bus): at t = 1 s the FMU's step fails; the
    emulator stops sending sensor frames, logs the reason on one line and exits 1."""
    sc = _scenario(tmp_path, fmus["fail_1s"], duration_s=2.0)
    summary = tmp_path / "emu.json"
    argv = [*FIRMWARE_SIM, "-c", EMU_CFG, "--interface", "virtual", "--channel", "fmu-fail"]
    proc = _cli([*argv, "--scenario", str(sc), "--summary-json", str(summary)], tmp_path)
    assert proc.returncode == 1, proc.stderr
    s = json.loads(summary.read_text())
    assert s["periods"] == 1000  # samples 0 … 999 stepped, the one at t = 1 s failed
    assert "fmi2DoStep returned Discard (step at t = 1.0000 s)" in s["plant_failure"]
    errors = [line for line in proc.stderr.splitlines() if ": ERROR: " in line]
    assert len(errors) == 1 and "emulator stopped (fail-safe" in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr


def test_without_fmpy_an_fmu_scenario_names_the_extra(tmp_path: Path) -> None:
    sc = _scenario(tmp_path / "sc", tmp_path / "axis.fmu")
    code = (
        "import sys\nsys.modules['fmpy'] = None\nfrom ehpss_hil.cli import main\n"
        f"sys.exit(main(['sim', {str(sc)!r}, '-C', 'nrc']))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "pip install 'ehpss-hil[fmu]'" in proc.stderr, proc.stderr


# ---- campaigns ------------------------------------------------------------------------------------
_CAMPAIGN = """\
name: fmu-campaign
base: {base}
samples: 4
modes: [nrc, mmac, oracle]
duration_s: 1.0
faults:
  count: [1, 1]
  onset_s: [0.0, 0.5]
  kinds:
    {kind}: {{weight: 1, magnitude: [0.5, 0.9]}}
"""


def test_a_campaign_on_the_fmu_checks_its_kinds_and_hashes_the_fmu(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    """A fault kind the FMU does not model is refused naming it; the content hash covers the
    FMU's bytes, so a campaign resumed on a changed FMU does not reuse the old runs."""
    from ehpss_hil.campaign.spec import load_campaign

    fmap = {k: v for k, v in TEST_FMU_MAP.items() if k != "k_q"}
    base = _scenario(tmp_path, fmus["good"], fmap=fmap)
    bad = tmp_path / "kq.yaml"
    bad.write_text(_CAMPAIGN.format(base=base.name, kind="kq"))
    proc = _cli([*EHPSS_HIL, "check-config", str(bad)], tmp_path)
    assert proc.returncode == 2
    assert "faults.kinds.kq: the base scenario's FMU plant does not model k_q" in proc.stderr
    camp = tmp_path / "loe.yaml"
    camp.write_text(_CAMPAIGN.format(base=base.name, kind="loe"))
    first = load_campaign(camp).content_hash
    assert load_campaign(camp).content_hash == first
    (tmp_path / fmus["good"].name).write_bytes(fmus["fail_1s"].read_bytes())
    assert load_campaign(camp).content_hash != first
