"""The wheel is complete: built from the sources, installed (not editable) into a fresh virtual
environment and run from another directory, it finds its DBC, EDS files and parameters.

Offline: the wheel is built without build isolation (setuptools of the test extra) and installed
with ``--no-index --no-deps``; the fresh environment reaches the dependencies through a path
entry naming this environment's site-packages, after its own (so the installed wheel, not the
editable source, is what runs: this environment's ``.pth`` files are not processed there)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: what a wheel is built from (an sdist's content)
SOURCES = ("pyproject.toml", "README.md", "ehpss_hil", "firmware_sim")


def _run(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    proc = subprocess.run(argv, capture_output=True, text=True, cwd=cwd, env=env, timeout=900)
    assert proc.returncode == 0, (argv, proc.stdout[-2000:], proc.stderr[-2000:])
    return proc


def _copy_sources(dest: Path) -> Path:
    """The files a wheel is built from (:data:`SOURCES`), copied to ``dest``, without caches."""
    dest.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, dest / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy(ROOT / name, dest / name)
    return dest


def _install_wheel(tmp_path: Path) -> Path:
    """Build the wheel from a copy of the sources, install it into a fresh venv; its bin/."""
    src = _copy_sources(tmp_path / "src")
    pip = [sys.executable, "-m", "pip"]
    dist = tmp_path / "dist"
    _run(
        [*pip, "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(dist), str(src)],
        tmp_path,
    )
    (wheel,) = dist.glob("ehpss_hil-*.whl")
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path)
    vpy = venv / "bin" / "python"
    _run([*pip, "--python", str(vpy), "install", "--no-deps", "--no-index", str(wheel)], tmp_path)
    site = _run([str(vpy), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], tmp_path)
    deps = sysconfig.get_path("purelib")
    (Path(site.stdout.strip()) / "ehpss-test-deps.pth").write_text(deps + "\n")
    return venv / "bin"


def _rms_row(out: str) -> list[str]:
    """The fields of ``sim``'s table row for case1-loe (scenario, mode, RMS µm, pre µm, sw, …)."""
    return next(line for line in out.splitlines() if line.startswith("case1-loe")).split()


@pytest.mark.slow
def test_the_installed_wheel_runs_sim_and_finds_its_data_from_another_directory(tmp_path: Path) -> None:
    bin_dir = _install_wheel(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(ROOT / "scenarios" / "case1-loe.yaml", work / "case1-loe.yaml")
    where = _run(
        [
            str(bin_dir / "python"),
            "-c",
            "import ehpss_hil as e\n"
            "from ehpss_hil.physics.params import DEFAULT_PARAMS\n"
            "from ehpss_hil.protocol.cia408.eds import ENCODER_EDS, VALVE_EDS, load_od\n"
            "assert 0x6300 in load_od(VALVE_EDS, 32) and 0x6004 in load_od(ENCODER_EDS, 33)\n"
            "print(e.__file__, e.DEFAULT_DBC, DEFAULT_PARAMS)",
        ],
        work,
    ).stdout.split()
    for path in where:  # the package and its data come from the installed wheel
        assert path.startswith(str(tmp_path / "venv")) and Path(path).is_file(), where
    sim = ["sim", "case1-loe.yaml", "-C", "nrc", "--jobs", "1"]
    row = _rms_row(_run([str(bin_dir / "ehpss-hil"), *sim], work).stdout)
    assert row[:2] == ["case1-loe", "nrc"] and 1.0 < float(row[2]) < 1000.0, row
    # the same figures as the source tree's (the run is deterministic; the data is the same)
    assert row[2:5] == _rms_row(_run([sys.executable, "-m", "ehpss_hil.cli", *sim], work).stdout)[2:5]
    assert _run([str(bin_dir / "ehpss-hil"), "--version"], work).stdout.split() == ["ehpss-hil", "0.1.0"]
