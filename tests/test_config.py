"""Configs and scenarios: every kind of bad input names the file, the key path and the reason."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.config import load_controller_config, load_emulator_config
from ehpss_hil.errors import ConfigError, EhpssError
from ehpss_hil.physics.load import load_params
from ehpss_hil.scenario import load_scenario

SCENARIOS = sorted((PROJECT_ROOT / "scenarios").glob("*.yaml"))

GOOD = """\
name: t
duration_s: 2.0
reference: {kind: sine, amplitude_m: 0.001, omega_rad_s: 5.0}
events:
  - {t_s: 0.5, k_loe: 0.8}
  - {t_s: 1.0, k_dft: 0.5}
  - {t_s: 1.5, k_loe: 0.2}
"""


def _write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_files_load() -> None:
    assert len(SCENARIOS) >= 5
    for p in SCENARIOS:
        s = load_scenario(p)
        assert s.n_samples == round(s.duration_s / s.sample_time_s)
    c = load_controller_config(PROJECT_ROOT / "configs/controller.yaml")
    assert c.mode == "mmac" and c.bus.hop_limit == 0
    assert Path(c.params).is_file() and Path(c.dbc).is_file()
    e = load_emulator_config(PROJECT_ROOT / "configs/emulator.yaml")
    assert Path(e.scenario).is_file()
    assert load_params().controller.k_f == 12.71


def test_case_events_persist_until_changed(tmp_path: Path) -> None:
    s = load_scenario(_write(tmp_path, GOOD))
    tl = s.fault_timeline()
    assert [k for k, _, _ in tl] == [0, 500, 1000, 1500]
    assert (tl[2][1].k_loe, tl[2][1].k_dft) == (0.8, 0.5)
    assert (tl[3][1].k_loe, tl[3][1].k_dft) == (0.2, 0.5)


@pytest.mark.parametrize(
    "mutation,key_path,reason",
    [
        (("k_loe: 0.2", "k_loe: 1.7"), "events[2].k_loe", "<= 1.5"),
        (("k_loe: 0.2", "k_lo: 0.2"), "events[2].k_lo", "unknown key"),
        (("k_loe: 0.2", "k_loe: fast"), "events[2].k_loe", "expected a number"),
        (("duration_s: 2.0", "duration_s: -1"), "duration_s", "> 0.0"),
        (("name: t\n", ""), "name", "missing required key"),
        (("kind: sine", "kind: sawtooth"), "reference.kind", "one of"),
        (("omega_rad_s: 5.0", "omega_rad_s: .nan"), "reference.omega_rad_s", "finite"),
        (("{t_s: 1.0, k_dft: 0.5}", "{t_s: 0.2, k_dft: 0.5}"), "events[1].t_s", "time order"),
        (("{t_s: 1.0, k_dft: 0.5}", "{t_s: 1.0}"), "events[1]", "at least one"),
        (("events:", "frame_loss: [1]\nevents:"), "frame_loss", "expected a number"),
    ],
)
def test_bad_scenario_names_key_path(
    tmp_path: Path, mutation: tuple[str, str], key_path: str, reason: str
) -> None:
    old, new = mutation
    assert old in GOOD
    p = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ConfigError) as exc:
        load_scenario(p)
    assert exc.value.key_path == key_path
    assert reason in exc.value.reason
    assert str(p) in str(exc.value)
    assert isinstance(exc.value, EhpssError) and isinstance(exc.value, ValueError)


def test_yaml_syntax_error_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="invalid YAML at line 2"):
        load_scenario(_write(tmp_path, "name: x\n  bad: [\n"))
    with pytest.raises(ConfigError, match="cannot read file"):
        load_scenario(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="expected a mapping"):
        load_scenario(_write(tmp_path, "- 1\n- 2\n"))


@pytest.mark.parametrize(
    "text,key_path,reason",
    [
        ("bus: {interface: udp_multicast, channel: 224.1.2.3}", "bus.channel", "239.0.0.0/8"),
        ("bus: {hop_limit: 1}", "bus.hop_limit", "<= 0"),
        ("bus: {interface: pcan}", "bus.interface", "one of"),
        ("bus: {interface: socketcan, channel: ''}", "bus.channel", "interface"),
        ("mode: oracle", "mode", "benchmarks only"),
        ("watchdog: {timeout_cycles: 0}", "watchdog.timeout_cycles", ">= 1"),
        ("watchdog: {failsafe: drift}", "watchdog.failsafe", "one of"),
        ("ids: {controller_node: 2, emulator_node: 2}", "ids.emulator_node", "differ"),
        ("tuning: {hysteresis: 2}", "tuning.hysteresis", "<= 1.0"),
        ("rate_hz: true", "rate_hz", "expected a number"),
        ("colour: blue", "colour", "unknown key"),
    ],
)
def test_bad_controller_config(tmp_path: Path, text: str, key_path: str, reason: str) -> None:
    with pytest.raises(ConfigError) as exc:
        load_controller_config(_write(tmp_path, text, "controller.yaml"))
    assert exc.value.key_path == key_path
    assert reason in exc.value.reason


def test_bad_params(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as exc:
        load_params(_write(tmp_path, "plant: {load_mass_kg: 0}\n", "params.yaml"))
    assert exc.value.key_path == "plant.load_mass_kg"


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ehpss_hil.cli", *args],
        capture_output=True,
        text=True,
        cwd=PROJECT_ROOT,
        check=False,
    )


def test_cli_check_config_ok_and_exit_2_on_broken_scenario(tmp_path: Path) -> None:
    ok = _cli(
        "check-config",
        *(str(p) for p in SCENARIOS),
        "configs/controller.yaml",
        "configs/emulator.yaml",
        "configs/params.yaml",
    )
    assert ok.returncode == 0, ok.stderr
    assert len(ok.stdout.strip().splitlines()) == len(SCENARIOS) + 3
    bad = _write(tmp_path, GOOD.replace("k_loe: 0.2", "k_loe: 7"))
    res = _cli("check-config", str(bad))
    assert res.returncode == 2
    assert "events[2].k_loe" in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_cli_help_lists_subcommands() -> None:
    res = _cli("--help")
    assert res.returncode == 0
    for cmd in ("check-config", "bench"):
        assert cmd in res.stdout
