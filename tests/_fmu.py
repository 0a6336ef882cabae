"""Helpers of the FMU plant tests: a scenario file with an FMU plant, the CLI in a subprocess."""

from __future__ import annotations

import subprocess
from pathlib import Path

import yaml
from _proc import ENV

from ehpss_hil.physics.fmutest import TEST_FMU_MAP


def scenario(
    d: Path,
    fmu: Path,
    *,
    fmap: dict[str, str] | None = None,
    events: list[dict[str, float]] | None = None,
    duration_s: float = 2.0,
) -> Path:
    """A scenario file in ``d`` with the FMU plant (its path relative to the file)."""
    data = {
        "name": f"fmu-{fmu.stem}",
        "duration_s": duration_s,
        "reference": {"kind": "sine", "amplitude_m": 0.001, "omega_rad_s": 5.0},
        "noise": {"position_m": 1.0e-6, "spool_m": 1.52e-6, "pressure_pa": 1.0e4},
        "events": events if events is not None else [{"t_s": 0.5, "k_loe": 0.5}],
        "plant": {"model": "fmu", "path": fmu.name, "fmu_map": TEST_FMU_MAP if fmap is None else fmap},
    }
    d.mkdir(parents=True, exist_ok=True)
    if fmu.exists() and fmu.parent != d:
        (d / fmu.name).write_bytes(fmu.read_bytes())
    path = d / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def cli(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """``argv`` run in ``cwd`` (output captured as text; a hang guard of 300 s only)."""
    return subprocess.run(argv, capture_output=True, text=True, cwd=cwd, env=ENV, timeout=300)
