"""Lean installs: the controller daemon and the emulator, run for real, import none of the
optional packages (the extras campaign, monitor, plot, mf4, and scipy); a command that needs a
missing extra says which one to install, on one line, and exits 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ehpss_hil.extras import EXTRAS

ROOT = Path(__file__).resolve().parent.parent
PY = sys.executable
#: top-level packages neither the daemon nor the emulator may load (every extra's modules)
FORBIDDEN = frozenset(m for mods in EXTRAS.values() for m in mods)
#: what the daemon and the emulator must not have loaded: asammdf (the mf4 extra) is looked for
#: by ``import can`` whether installed or not (importtime lists the attempt; ``import ehpss_hil``
#: hides it from python-can), so what shows that it was not loaded is pandas, which it imports
NOT_LOADED = (FORBIDDEN - {"asammdf"}) | {"pandas"}


def _imported_by(argv: list[str], cwd: Path) -> set[str]:
    """Top-level names of every module ``python -X importtime argv`` imported (the process runs
    to its end; exit 0 asserted)."""
    proc = subprocess.run(
        [PY, "-X", "importtime", *argv], capture_output=True, text=True, cwd=cwd, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    names = set()
    for line in proc.stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            name = line.rsplit("|", 1)[1].strip()
            if name != "imported package":
                names.add(name.split(".")[0])
    return names


@pytest.mark.parametrize(
    ("program", "config"),
    [("ehpss_hil.cli controller", "controller.yaml"), ("firmware_sim.cli", "emulator.yaml")],
)
def test_the_daemon_and_the_emulator_run_without_optional_packages(
    program: str, config: str, tmp_path: Path
) -> None:
    """Each program configured, on a bus, running its loop for 0.3 s (python-can's in-process
    virtual bus: the same code path as udp_multicast above the bus)."""
    argv = ["-m", *program.split(), "-c", str(ROOT / "configs" / config)]
    names = _imported_by([*argv, "--interface", "virtual", "--duration", "0.3"], tmp_path)
    assert {"numpy", "cantools", "can", "yaml"} <= names  # the parse saw the real imports
    assert not names & NOT_LOADED, sorted(names & NOT_LOADED)


def _with_blocked(blocked: set[str], args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """``ehpss-hil args`` in a fresh interpreter where the modules ``blocked`` cannot be imported
    (as when their extra is not installed)."""
    code = (
        "import sys\n"
        f"for m in {sorted(blocked)!r}:\n"
        "    sys.modules[m] = None\n"
        "from ehpss_hil.cli import main\n"
        f"sys.exit(main({args!r}))\n"
    )
    return subprocess.run([PY, "-c", code], capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.mark.parametrize(
    ("args", "blocked", "extra"),
    [
        (["campaign", str(ROOT / "campaigns" / "quick.yaml"), "--no-figures"], {"pyarrow"}, "campaign"),
        (
            ["campaign", str(ROOT / "campaigns" / "quick.yaml"), "--scheduler", "tcp://h:1"],
            {"dask"},
            "campaign",
        ),
        (["bench", "campaign", "--no-dask"], {"scipy"}, "campaign"),
        (["monitor"], {"aiohttp"}, "monitor"),
        (["bench", "monitor"], {"aiohttp"}, "monitor"),
        (
            ["sim", str(ROOT / "scenarios" / "case1-loe.yaml"), "-C", "nrc", "--plot", "x.png"],
            {"matplotlib"},
            "plot",
        ),
        (["report", "no-such.log"], {"matplotlib"}, "plot"),
        (
            [
                "identify",
                "--scenario",
                str(ROOT / "scenarios" / "identify" / "kq075.yaml"),
                "--out",
                "P.yaml",
            ],
            {"scipy"},
            "identify",
        ),
        (["log", "-i", "virtual", "-c", "lean", "-o", "bus.mf4"], {"asammdf"}, "mf4"),
    ],
)
def test_a_missing_extra_is_one_line_naming_it_and_exit_2(
    args: list[str], blocked: set[str], extra: str, tmp_path: Path
) -> None:
    proc = _with_blocked(blocked | (FORBIDDEN - set(EXTRAS[extra])), args, tmp_path)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr[-2000:]
    assert f"pip install 'ehpss-hil[{extra}]'" in lines[0]
    assert sorted(blocked)[0] in lines[0]
    assert not list(tmp_path.iterdir())  # refused before it wrote anything


def test_every_command_parses_and_sim_runs_without_any_extra(tmp_path: Path) -> None:
    """With every optional package missing, each command's arguments still parse (``bench``
    loads all its benchmark modules) and ``sim`` runs."""
    for cmd in (["bench", "loop", "--help"], ["campaign", "--help"], ["monitor", "--help"]):
        proc = _with_blocked(set(FORBIDDEN), cmd, tmp_path)
        assert proc.returncode == 0, (cmd, proc.stderr[-2000:])
    proc = _with_blocked(
        set(FORBIDDEN), ["sim", str(ROOT / "scenarios" / "case1-loe.yaml"), "-C", "nrc"], tmp_path
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "case1" in proc.stdout and "nrc" in proc.stdout
