"""The programs under a small address-space limit (``ulimit -v``): they run and exit instead of
spinning in OpenBLAS's thread-pool start-up (two OpenBLAS libraries, numpy's and scipy's, with
more than one thread each, spin there; the programs load numpy's only, held to one thread
unless the user chose otherwise). Each command has a generous timeout: a hang fails the test,
a slow host does not."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from _proc import ROOT

BIN = Path(sys.executable).parent
SCENARIO = "name: tiny\nduration_s: 0.05\nevents:\n  - {t_s: 0.02, k_dft: 0.5}\n"


def _limited(kb: int, argv: list[str], env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    cmd = f"ulimit -v {kb} && exec {shlex.join(argv)}"
    return subprocess.run(["bash", "-c", cmd], cwd=ROOT, env=env, capture_output=True, text=True, timeout=180)


def _env(openblas_threads: str | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    if openblas_threads is not None:
        env["OPENBLAS_NUM_THREADS"] = openblas_threads  # the user's choice is kept
    return env


def _programs(sc: Path) -> dict[str, list[str]]:
    return {
        "sim": [str(BIN / "ehpss-hil"), "sim", str(sc), "-C", "mmac", "--transport", "frames"],
        "controller": [
            *(str(BIN / "ehpss-hil"), "controller", "-c", "configs/controller.yaml"),
            *("--interface", "virtual", "--mode", "mmac", "--duration", "0.1"),
        ],
        "emulator": [
            *(str(BIN / "firmware-sim"), "-c", "configs/emulator.yaml", "--interface", "virtual"),
            *("--scenario", str(sc), "--duration", "0.1"),
        ],
        "help": [str(BIN / "firmware-sim"), "--help"],
    }


@pytest.mark.parametrize("kb", [300_000, 200_000])
def test_sim_controller_and_emulator_run_under_ulimit_v(kb: int, tmp_path: Path) -> None:
    """With the programs' own BLAS setting (one thread) every program runs to its end: exit 0,
    the simulator's table printed, the controller's cycles counted."""
    sc = tmp_path / "tiny.yaml"
    sc.write_text(SCENARIO)
    for name, argv in _programs(sc).items():
        r = _limited(kb, argv, _env(None))
        assert r.returncode == 0, (name, r.stderr[-2000:])
        if name == "sim":
            assert "tiny" in r.stdout and "mmac" in r.stdout
        if name == "controller":  # 100 periods of 1 ms; on a loaded host skipped periods count too
            m = re.search(r"controller: cycles (\d+), final state STOPPED", r.stdout + r.stderr)
            assert m is not None and int(m.group(1)) >= 100, (r.stdout + r.stderr)[-2000:]


def test_many_blas_threads_the_user_chose_fail_fast_in_one_line(tmp_path: Path) -> None:
    """OPENBLAS_NUM_THREADS=8 (kept: the user's choice) at 200 MB: each BLAS thread's buffers
    leave too little address space, and where the first allocation then fails is chance (a
    MemoryError, a parse error of the DBC, or a library retrying for ever: seen on a loaded host).
    Every program refuses at start with one line naming the limit, exit 1 — never spinning, never
    a traceback (``--help`` needs no BLAS and still prints)."""
    sc = tmp_path / "tiny.yaml"
    sc.write_text(SCENARIO)
    for name, argv in _programs(sc).items():
        r = _limited(200_000, argv, _env("8"))
        lines = r.stderr.strip().splitlines()
        if name == "help":  # argparse's help needs no BLAS: printed before any check
            assert r.returncode == 0 and "usage:" in r.stdout, r.stderr[-2000:]
            continue
        assert (
            r.returncode == 1
            and len(lines) == 1
            and "error: out of memory (refused at start)" in lines[0]
            and "address-space limit 195 MiB (ulimit -v), OPENBLAS_NUM_THREADS=8" in lines[0]
        ), (name, r.returncode, r.stderr[-2000:])
