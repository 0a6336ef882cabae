"""The local pool of ``ehpss-hil campaign --workers 2`` when a worker process is killed from
outside (the OOM killer, ``kill -9``): the lost worker's runs run again and the campaign ends
with the undisturbed table; workers killed again and again stop it with one line, and
``--resume`` finishes it with the same table. Real processes, found through /proc; no timing
asserts (the waits only keep a broken run from hanging)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
from _campaign import LIMIT_S, cli, digest, tiny, wait_lines
from _proc import EHPSS_HIL, ENV, ROOT

from ehpss_hil.campaign.journal import JOURNAL_NAME, read_journal
from ehpss_hil.campaign.localpool import LOSSES_PER_ATTEMPT, run_local
from ehpss_hil.campaign.runs import RunTask
from ehpss_hil.campaign.sampling import plan_runs
from ehpss_hil.campaign.session import run_campaign
from ehpss_hil.campaign.spec import load_campaign
from ehpss_hil.campaign.workers import Tally
from ehpss_hil.errors import ModelError

#: runs of the campaigns here: far more than finish between a journal line and a kill
SAMPLES = 40
#: how often the killer looks for new pool workers (s)
POLL_S = 0.005


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The campaign file and its table from one worker in this process."""
    d = tmp_path_factory.mktemp("lost")
    f = tiny(d / "tiny.yaml", samples=SAMPLES)
    run_campaign(load_campaign(f), d / "one", workers=1, figures=False)
    return f, d / "one"


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` and which run its program (its forked pool workers),
    from /proc/<pid>/stat and /proc/<pid>/cmdline."""
    try:
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return []
    found = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            same = (d / "cmdline").read_bytes() == cmdline
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid and same:
            found.append(int(d.name))
    return found


def _campaign(f: Path, out: Path, *extra: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [*EHPSS_HIL, "campaign", str(f), "--workers", "2", "--out", str(out), "--no-figures", *extra],
        cwd=ROOT,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )


def _finish(proc: subprocess.Popen[bytes]) -> tuple[str, str]:
    try:
        stdout, stderr = proc.communicate(timeout=LIMIT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return stdout.decode(), stderr.decode()


def test_a_worker_killed_mid_campaign_is_replaced_and_the_table_is_unchanged(
    reference: tuple[Path, Path], tmp_path: Path
) -> None:
    f, one = reference
    out = tmp_path / "killed"
    proc = _campaign(f, out)
    try:
        wait_lines(out / JOURNAL_NAME, 2, proc)
        workers = _children(proc.pid)
        assert len(workers) == 2, f"pool workers of {proc.pid}: {workers}"
        os.kill(workers[0], signal.SIGKILL)
    finally:
        stdout, stderr = _finish(proc)
    assert proc.returncode == 0, stdout + stderr
    assert re.search(rf"{SAMPLES} run\(s\) done .*, 1 worker lost, [12] runs? retried", stdout), stdout
    assert re.search(r"runs/s, ETA \S+, 1 worker lost, [12] runs? retried", stderr), stderr  # progress
    summary = (out / "summary.md").read_text()
    assert f"1 worker lost (local process {workers[0]} (SIGKILL))" in summary, summary
    assert "Traceback" not in stderr
    assert digest(out) == digest(one)
    assert len(read_journal(out / JOURNAL_NAME)) == SAMPLES  # each run once: none twice, none torn
    again = cli("campaign", str(f), "--workers", "2", "--out", str(out), "--resume", "--no-figures")
    assert again.returncode == 0 and f"0 run(s) done, {SAMPLES} skipped" in again.stdout, again.stdout


def test_workers_killed_again_and_again_stop_the_campaign_with_one_line_and_resume_finishes(
    reference: tuple[Path, Path], tmp_path: Path
) -> None:
    f, one = reference
    out = tmp_path / "killing"
    proc = _campaign(f, out)
    killed: set[int] = set()
    try:
        while proc.poll() is None:  # every pool worker, as soon as it is seen, until the end
            for pid in set(_children(proc.pid)) - killed:
                os.kill(pid, signal.SIGKILL)
                killed.add(pid)
            time.sleep(POLL_S)
    finally:
        stdout, stderr = _finish(proc)
    assert proc.returncode == 1, stdout + stderr
    lines = stderr.strip().splitlines()
    assert re.fullmatch(
        rf"ehpss-hil campaign: error: run \d+ lost {LOSSES_PER_ATTEMPT} local worker processes in each "
        r"of its 1 attempt\(s\) .*; the finished runs are kept in .*: continue with --resume",
        lines[-1],
    ), stderr
    assert "Traceback" not in stderr and len(killed) >= LOSSES_PER_ATTEMPT
    kept = len(read_journal(out / JOURNAL_NAME)) if (out / JOURNAL_NAME).exists() else 0
    assert kept < SAMPLES
    again = cli("campaign", str(f), "--workers", "2", "--out", str(out), "--resume", "--no-figures")
    assert again.returncode == 0, again.stderr
    assert f"{SAMPLES - kept} run(s) done" in again.stdout
    assert digest(out) == digest(one)


def test_a_failing_run_is_retried_on_the_pool_then_its_own_error_is_raised(
    reference: tuple[Path, Path],
) -> None:
    f, _one = reference
    camp = load_campaign(f)
    plans = plan_runs(camp)[:3]
    good = [RunTask(p.index, p.run_hash, p.scenario, camp.spec.modes) for p in plans[:2]]
    bad = RunTask(plans[2].index, plans[2].run_hash, plans[2].scenario, ("no-such-mode",))
    done: list[int] = []
    tally = Tally()
    with pytest.raises(ModelError, match="no-such-mode"):
        run_local([bad, *good], 2, lambda rec: done.append(rec["index"]), tally, retries=2)
    assert tally.retried == [bad.index, bad.index] and tally.lost_workers == []
    one = Tally()
    with pytest.raises(ModelError, match="no-such-mode"):  # in this process: the same
        run_local([bad], 1, lambda rec: done.append(rec["index"]), one, retries=1)
    assert one.retried == [bad.index]
