"""Helpers of the campaign tests: a tiny campaign file of 0.5-s runs, the table's digest, the CLI."""

from __future__ import annotations

import hashlib
import subprocess
import time
from pathlib import Path

from _proc import EHPSS_HIL, ENV, ROOT

from ehpss_hil.campaign.table import PARQUET_NAME

TINY = """\
name: tiny
base: {base}
samples: {samples}
sampler: lhs
seed: 3
duration_s: 0.5
faults:
  count: [1, 2]
  onset_s: [0.0, 0.3]
  ramp_s: [0.05, 0.2]
  ramp_share: 0.5
  kinds: {{loe: {{magnitude: [0.3, 0.8]}}, drift: {{}}, stuck: {{}}, bias: {{}}, frame_loss: {{}}}}
reference: {{kinds: [sine, square], amplitude_m: [0.0005, 0.002], omega_rad_s: [3.0, 8.0]}}
noise_scale: [0.5, 2.0]
"""
#: waits that only keep a broken run from hanging (s)
LIMIT_S = 300.0


def tiny(path: Path, samples: int = 8) -> Path:
    path.write_text(TINY.format(base=ROOT / "scenarios" / "case1-loe.yaml", samples=samples))
    return path


def digest(out: Path) -> str:
    return hashlib.sha256((out / PARQUET_NAME).read_bytes()).hexdigest()


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*EHPSS_HIL, *args], cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=LIMIT_S, check=False
    )


def wait_lines(journal: Path, n: int, proc: subprocess.Popen[bytes]) -> int:
    """Block until ``journal`` holds ``n`` lines (AssertionError when ``proc`` ends first)."""
    deadline = time.monotonic() + LIMIT_S
    while time.monotonic() < deadline and proc.poll() is None:
        if journal.exists() and journal.read_bytes().count(b"\n") >= n:
            return journal.read_bytes().count(b"\n")
        time.sleep(0.01)
    raise AssertionError(f"the campaign ended (rc {proc.returncode}) or stalled before {n} runs")
