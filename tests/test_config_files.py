"""Hostile config and scenario files (issue #16 item 3): caps on reading, values the programs
cannot run with, and trajectory files read once at load time."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.commands.check_config import summarize
from ehpss_hil.config import load_controller_config
from ehpss_hil.errors import ConfigError
from ehpss_hil.limits import MAX_YAML_BYTES
from ehpss_hil.orchestrate import RunPlan, _commands
from ehpss_hil.scenario import ReferenceBlocks, load_scenario

CASE1 = (PROJECT_ROOT / "scenarios" / "case1-loe.yaml").read_text()


def _bomb(levels: int) -> str:
    lines = ['a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


HOSTILE: dict[str, bytes] = {
    "bomb.yaml": _bomb(9).encode(),
    "latin1.yaml": b"name: caf\xe9\n",
    "deep.yaml": b"a: " + b"[" * 2000 + b"]" * 2000 + b"\n",
    "control.yaml": b"name: a\x07b\n",
    "reader.yaml": b"name: x\x00\n",
    "bigint.yaml": b"name: x\nduration_s: " + b"9" * 5000 + b"\n",
    "date.yaml": b"name: 2024-13-45\n",
    "events.yaml": b"name: x\nduration_s: 1\nevents:\n"
    + b"  - {t_s: 0.5, k_loe: 0.5}\n" * (MAX_YAML_BYTES // 25),
}


#: a small launcher between the test and the command: a child forked straight from the test
#: process inherits its resident size into ru_maxrss (the high-water mark survives exec), so a
#: test process grown to 200 MB by earlier tests made every command "use" 200 MB
_LAUNCH = (
    "import os, subprocess, sys\n"
    "p = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL)\n"
    "_, status, usage = os.wait4(p.pid, 0)\n"
    "print(usage.ru_maxrss * 1024)\n"
    "sys.exit(os.waitstatus_to_exitcode(status))\n"
)


def _run_capped(argv: list[str]) -> tuple[int, str, float, int]:
    """Run a command; returns exit code, stderr, wall time (s) and the command's peak RSS
    (bytes)."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", _LAUNCH, *argv], capture_output=True, text=True, cwd=PROJECT_ROOT
    )
    return proc.returncode, proc.stderr, time.perf_counter() - t0, int(proc.stdout.strip())


def test_hostile_files_are_one_line_exit_2(tmp_path: Path) -> None:
    """Each file: exit 2, one line naming it, well under 200 MB; all in one process."""
    paths = []
    for name, data in HOSTILE.items():
        (tmp_path / name).write_bytes(data)
        paths.append(str(tmp_path / name))
    os.mkfifo(tmp_path / "fifo.yaml")
    paths += [str(tmp_path / "fifo.yaml"), "/dev/zero", str(tmp_path)]
    rc, err, wall, rss = _run_capped([sys.executable, "-m", "ehpss_hil.cli", "check-config", *paths])
    lines = err.strip().splitlines()
    assert rc == 2
    assert len(lines) == len(paths), err
    for p, line in zip(paths, lines, strict=True):
        assert line.startswith(f"{p}: ERROR: {p}: "), line
        assert len(line) < 600
    assert wall < 120.0  # a hang guard only (the files take well under 1 s each on a quiet host)
    assert rss < 200 * 2**20, f"{rss / 2**20:.0f} MB"
    assert "aliases" in lines[0] and "not UTF-8" in lines[1] and "deeper" in lines[2]
    assert "FIFO" in lines[-3] and "device" in lines[-2] and "directory" in lines[-1]
    assert "larger than" in lines[len(HOSTILE) - 1]


def _write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "text,key_path",
    [
        ("tuning: {epsilon0: 1.0e300}", "tuning.epsilon0"),
        ("tuning: {guard_epsilon: 1.0e300}", "tuning.guard_epsilon"),
        ("tuning: {position_guard_epsilon: 1.0e300}", "tuning.position_guard_epsilon"),
        ("tuning: {nlms_c_fraction: 1.0e300}", "tuning.nlms_c_fraction"),
        ("tuning: {dwell_s: 1.7e308}", "tuning.dwell_s"),
        ("tuning: {warmup_s: 1.7e308}", "tuning.warmup_s"),
        ("tuning: {k_loe_limits: [0.5]}", "tuning.k_loe_limits"),
        ("tuning: {k_loe_limits: [1.0, 0.5]}", "tuning.k_loe_limits"),
        ("tuning: {fixed_k_dft: [1, 0.5, 0, 0.2]}", "tuning.fixed_k_dft"),
        ("tuning: {nlms_gain_per_ms: 1.5}", "tuning.nlms_gain_per_ms"),
        ("stats_interval_s: 1.7e308", "stats_interval_s"),
        ("reference: {amplitude_m: 1.0e-300}", "reference.amplitude_m"),
        ("reference: {kind: ramp, rate_m_s: -1.0e-300}", "reference.rate_m_s"),
        ("ids: {id_base: 0x6F0}", "ids.id_base"),
        ("rt: {sensor_age_us: 600}", "rt.sensor_age_us"),
        ("rate_hz: 1.0e400", "rate_hz"),
        ("rate_hz: 99999999999999999999999999999999999999999999999999999999", "rate_hz"),
    ],
)
def test_controller_values_the_daemon_cannot_run(tmp_path: Path, text: str, key_path: str) -> None:
    p = _write(tmp_path, "controller.yaml", text + "\n")
    with pytest.raises(ConfigError) as exc:
        summarize(p)
    assert exc.value.key_path == key_path
    assert str(exc.value).startswith(f"{p}: {key_path}: ")


@pytest.mark.parametrize(
    "text,key_path",
    [
        ("plant: {flow_gain_1_s3: 1.0e300}", "plant.flow_gain_1_s3"),
        ("plant: {load_mass_kg: 1.0e-300}", "plant.load_mass_kg"),
        ("controller: {k_p: 1000}", "controller"),
    ],
)
def test_params_the_plant_cannot_run(tmp_path: Path, text: str, key_path: str) -> None:
    with pytest.raises(ConfigError) as exc:
        summarize(_write(tmp_path, "params.yaml", text + "\n"))
    assert exc.value.key_path == key_path


def test_scenario_duration_bounded_by_samples(tmp_path: Path) -> None:
    p = _write(tmp_path, "s.yaml", CASE1.replace("duration_s: 4.0", "duration_s: 86400"))
    with pytest.raises(ConfigError, match="samples") as exc:
        load_scenario(p)
    assert exc.value.key_path == "duration_s"
    p = _write(tmp_path, "s.yaml", "name: x\nduration_s: 1.0e-300\n")
    with pytest.raises(ConfigError, match="samples"):
        load_scenario(p)


def _file_scenario(tmp: Path, csv: str, path: str = "traj.csv") -> Path:
    (tmp / "traj.csv").write_text(csv)
    return _write(tmp, "s.yaml", f"name: f\nduration_s: 0.5\nreference: {{kind: file, path: {path}}}\n")


def test_reference_file_loaded_once_relative_to_the_scenario(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sub = tmp_path / "sc"
    sub.mkdir()
    p = _file_scenario(sub, "0,0\n0.1,0.001\n1,0.001\n")
    monkeypatch.chdir(tmp_path)  # not the scenario's directory
    sc = load_scenario(p)
    assert Path(sc.reference.path) == sub / "traj.csv"
    (sub / "traj.csv").unlink()  # removed mid-run: the table is in memory
    xd = sc.reference_samples()
    assert xd[0] == 0.0 and xd[50] == pytest.approx(0.0005) and xd[-1] == 0.001
    blocks = ReferenceBlocks(sc.reference, 1e-3, block=100)
    assert [blocks.at(k) for k in (0, 50, 150, 499)] == pytest.approx([0, 5e-4, 1e-3, 1e-3])


@pytest.mark.parametrize(
    "csv,reason",
    [
        ("0\n1\n", "two columns"),
        ("0,0\n0,0.001\n", "time must increase"),
        ("0,0\n1,nan\n", "finite"),
        ("0,0\n1,2\n", "above"),
        ("", "no rows"),
        ("t,x\n0,0\n", "not a CSV of numbers"),
    ],
)
def test_bad_reference_file(tmp_path: Path, csv: str, reason: str) -> None:
    p = _file_scenario(tmp_path, csv)
    with pytest.raises(ConfigError, match=reason) as exc:
        load_scenario(p)
    assert exc.value.key_path == "reference.path" and exc.value.source == str(p)


def test_reference_fifo_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "fifo.csv")
    p = _file_scenario(tmp_path, "0,0\n", "fifo.csv")
    with pytest.raises(ConfigError, match="FIFO") as exc:
        load_scenario(p)
    assert exc.value.key_path == "reference.path"


def test_run_configs_keep_the_reference_file(tmp_path: Path) -> None:
    """``ehpss-hil run`` writes the controller's config into the run directory: a relative
    trajectory path of the scenario still names the same file (as for ``sim``)."""
    sub = tmp_path / "sc"
    sub.mkdir()
    sc_path = _file_scenario(sub, "0,0\n1,0.001\n")
    out = tmp_path / "run"
    out.mkdir()
    _commands(RunPlan(scenario_path=sc_path, out_dir=out), load_scenario(sc_path), out)
    cfg = load_controller_config(out / "controller.yaml")
    assert cfg.reference.table is not None
    np.testing.assert_allclose(cfg.reference.sample(np.array([0.5])), [0.0005])
