"""``ehpss-hil run`` as a real process says whether its realtime figures are valid: first line of
its output, ``realtime_valid``/``realtime_reasons`` in metrics.json, exit 4 when not valid. A
lockstep run is valid by construction; a controller SIGSTOPped for 0.5 s in mid-run is not (the
host "did not hold the rate" for half a second). No timing is asserted: the stop is far beyond
every threshold, and the waits are hang guards only."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from _proc import EHPSS_HIL, ENV, ROOT
from _scenarios import short_scenario_yaml

from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.runtime.rtverdict import LOCKSTEP_REASON, REALTIME_INVALID_EXIT

NETNS_SKIP = netns_unavailable_reason()
pytestmark = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
HANG_GUARD_S = 600.0


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("verdict") / "short-loe.yaml"
    p.write_text(short_scenario_yaml("short-loe", 2.5, "{t_s: 0.3, k_loe: 0.5}"))
    return p


def _run_cli(scenario: Path, out: Path, *extra: str) -> subprocess.Popen[str]:
    argv = [*EHPSS_HIL, "run", str(scenario), "--out", str(out), *extra]
    return subprocess.Popen(
        argv, cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _finish(p: subprocess.Popen[str]) -> tuple[int, list[str], str]:
    stdout, stderr = p.communicate(timeout=HANG_GUARD_S)
    return p.returncode, stdout.splitlines(), stderr


def _row(out: Path) -> dict[str, object]:
    rows = json.loads((out / "metrics.json").read_text())
    assert isinstance(rows, list) and len(rows) == 1
    row: dict[str, object] = rows[0]
    return row


def test_a_lockstep_run_is_valid_and_says_so_first(scenario: Path, tmp_path: Path) -> None:
    rc, lines, err = _finish(_run_cli(scenario, tmp_path / "ls", "--lockstep"))
    assert rc == 0, err
    assert lines[0] == f"realtime: valid ({LOCKSTEP_REASON})", lines
    assert lines[1].startswith("short-loe mmac: RMS ") and not any(ln.startswith("{") for ln in lines)
    row = _row(tmp_path / "ls")
    assert row["realtime_valid"] is True and row["realtime_reasons"] == [LOCKSTEP_REASON]


def test_a_realtime_run_writes_its_verdict_and_exits_by_it(scenario: Path, tmp_path: Path) -> None:
    """Valid or not depends on this host's load; what must hold: the verdict is in metrics.json,
    printed first, and the exit code follows it."""
    rc, lines, err = _finish(_run_cli(scenario, tmp_path / "rt"))
    row = _row(tmp_path / "rt")
    valid = row["realtime_valid"]
    assert isinstance(valid, bool) and isinstance(row["realtime_reasons"], list)
    assert rc == (0 if valid else REALTIME_INVALID_EXIT), (rc, row, err)
    if valid:
        assert lines[0] == "realtime: valid" and row["realtime_reasons"] == []
    else:
        assert lines[0].startswith("realtime: NOT VALID — ") and row["realtime_reasons"]
        assert "--lockstep" in lines[0]


def _pid_of(marker: str) -> int | None:
    """The process whose command line contains ``marker``."""
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if marker in cmd and "nsenter" not in cmd.split()[0]:
            return int(d.name)
    return None


def _wait_for(path: Path, text: str, p: subprocess.Popen[str]) -> None:
    end = time.monotonic() + HANG_GUARD_S
    while time.monotonic() < end and p.poll() is None:
        if path.exists() and text in path.read_text(errors="replace"):
            return
        time.sleep(0.02)
    raise AssertionError(f"{text!r} never in {path}")


def test_a_controller_stopped_for_half_a_second_makes_the_run_not_valid(
    scenario: Path, tmp_path: Path
) -> None:
    out = tmp_path / "stopped"
    p = _run_cli(scenario, out)
    try:
        _wait_for(out / "controller.out", "first sensor data: ACTIVE", p)
        pid = _pid_of(str(out / "controller-summary.json"))
        assert pid is not None
        os.kill(pid, signal.SIGSTOP)
        time.sleep(0.5)
        os.kill(pid, signal.SIGCONT)
        rc, lines, err = _finish(p)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert rc == REALTIME_INVALID_EXIT, (rc, lines, err)
    row = _row(out)
    reasons = row["realtime_reasons"]
    assert row["realtime_valid"] is False and isinstance(reasons, list)
    assert any("LOOP_OVERRUN" in r or r.startswith("controller skipped") for r in reasons), reasons
    assert lines[0].startswith("realtime: NOT VALID — "), lines
