"""Campaigns on Dask, with a real scheduler and real worker processes: a ``distributed.LocalCluster``
started by the campaign (``--scheduler local:2``) or by the test (``--scheduler tcp://…``). The
table is the one of a single local worker, byte for byte, even when a worker is killed with
SIGKILL mid-campaign (Dask reruns its runs; the campaign reports the lost worker). No timing
asserts: the waits only keep a broken run from hanging."""

from __future__ import annotations

import logging
import os
import re
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest
from _campaign import LIMIT_S, cli, digest, tiny, wait_lines
from _proc import EHPSS_HIL, ENV, ROOT
from distributed import Client, LocalCluster

from ehpss_hil.campaign.cluster import (
    HEARTBEAT_LOST,
    SYNC_MODULE_TAIL,
    DaskExecutor,
    SchedulerGoneFilter,
    SyncCancelFilter,
)
from ehpss_hil.campaign.journal import JOURNAL_NAME
from ehpss_hil.campaign.runs import RunTask
from ehpss_hil.campaign.sampling import plan_runs
from ehpss_hil.campaign.session import run_campaign
from ehpss_hil.campaign.spec import load_campaign
from ehpss_hil.campaign.workers import Tally
from ehpss_hil.errors import ModelError

#: runs of the campaign a worker is killed in: enough that many are left after the kill
SAMPLES = 24
#: the journal lines seen before a worker is killed
KILL_AFTER_RUNS = 2


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The campaign file and its table from one worker in this process."""
    d = tmp_path_factory.mktemp("dask")
    f = tiny(d / "tiny.yaml", samples=SAMPLES)
    run_campaign(load_campaign(f), d / "one", workers=1, figures=False)
    return f, d / "one"


def test_a_scheduler_address_gives_the_bit_identical_table(
    reference: tuple[Path, Path], tmp_path: Path
) -> None:
    f, one = reference
    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        host="127.0.0.1",
        dashboard_address=":0",
        silence_logs=logging.ERROR,
    ) as cluster:
        out = cli("campaign", str(f), "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "d"))
        link = cluster.dashboard_link
    assert out.returncode == 0, out.stderr
    assert f"on Dask scheduler {cluster.scheduler_address}" in out.stdout
    assert link.startswith("http://127.0.0.1:") and f"Dask dashboard: {link}\n" in out.stdout
    assert f"{SAMPLES} run(s) done" in out.stdout and "lost" not in out.stdout
    assert f"campaign: {SAMPLES}/{SAMPLES} runs (100.0 %)" in out.stderr and "runs/s, ETA" in out.stderr
    assert digest(tmp_path / "d") == digest(one)


def _scheduler_of(stdout: Path, proc: subprocess.Popen[bytes]) -> str:
    """The LocalCluster's scheduler address from the campaign's first line (in ``stdout``)."""
    deadline = time.monotonic() + LIMIT_S
    while time.monotonic() < deadline and proc.poll() is None:
        if m := re.search(r"scheduler (tcp://127\.0\.0\.1:\d+)\)", stdout.read_text()):
            return m.group(1)
        time.sleep(0.05)
    raise AssertionError(f"no scheduler address (rc {proc.returncode}): {stdout.read_text()}")


def test_a_worker_killed_mid_campaign_is_reported_and_the_table_is_unchanged(
    reference: tuple[Path, Path], tmp_path: Path
) -> None:
    f, one = reference
    out = tmp_path / "killed"
    logs = tmp_path / "stdout", tmp_path / "stderr"
    with open(logs[0], "wb") as o, open(logs[1], "wb") as e:
        proc = subprocess.Popen(
            [*EHPSS_HIL, "campaign", str(f), "--scheduler", "local:2", "--retries", "1", "--out", str(out)],
            cwd=ROOT,
            env=ENV,
            stdout=o,
            stderr=e,
            start_new_session=True,
        )
    try:
        with Client(_scheduler_of(logs[0], proc), timeout=LIMIT_S, set_as_default=False) as client:
            wait_lines(out / JOURNAL_NAME, KILL_AFTER_RUNS, proc)
            victim = sorted(client.scheduler_info()["workers"])[0]
            pid = client.run(os.getpid, workers=[victim])[victim]
            os.kill(pid, signal.SIGKILL)
        proc.wait(timeout=LIMIT_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    stdout, stderr = (p.read_text() for p in logs)
    assert proc.returncode == 0, stdout + stderr
    assert "Dask LocalCluster (2 worker processes × 1 thread" in stdout
    assert "Dask dashboard: http://127.0.0.1:" in stdout, stdout[:600]
    assert re.search(rf"{SAMPLES} run\(s\) done .*, 1 worker lost, \d+ runs? retried", stdout), stdout
    assert re.search(r"runs/s, ETA \S+, 1 worker lost, \d+ runs? retried", stderr), stderr  # progress
    summary = (out / "summary.md").read_text()
    assert f"1 worker lost ({victim})" in summary, summary
    assert "Traceback" not in stderr
    assert digest(out) == digest(one)


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_an_unreachable_scheduler_leaves_nothing_and_the_plain_rerun_works(
    reference: tuple[Path, Path], tmp_path: Path
) -> None:
    f, _one = reference
    out = tmp_path / "o"
    address = f"tcp://127.0.0.1:{_closed_port()}"
    gone = cli("campaign", str(f), "--scheduler", address, "--connect-timeout", "2", "--out", str(out))
    assert gone.returncode == 3, gone.stderr
    assert "cannot reach the Dask scheduler" in gone.stderr and "Traceback" not in gone.stderr
    assert "after 2 s" in gone.stderr, gone.stderr  # the timeout given, not the default 30 s
    assert not (out / JOURNAL_NAME).exists()
    tiny(f.parent / "two.yaml", samples=2)
    again = cli("campaign", str(f.parent / "two.yaml"), "--workers", "1", "--out", str(out), "--no-figures")
    assert again.returncode == 0, again.stderr
    assert "2 run(s) done" in again.stdout


@pytest.mark.parametrize(
    ("args", "key"),
    [
        (["--scheduler", "local:0"], "--scheduler"),
        (["--scheduler", "local:two"], "--scheduler"),
        (["--scheduler", "local:100000"], "--scheduler"),
        (["--retries", "101"], "--retries"),
        (["--scheduler", "tcp://127.0.0.1:8786", "--connect-timeout", "0"], "--connect-timeout"),
        (["--scheduler", "tcp://127.0.0.1:8786", "--connect-timeout", "nan"], "--connect-timeout"),
        (["--scheduler", "local:1", "--retries", "-1"], "--retries"),
    ],
)
def test_bad_scheduler_or_retries_is_one_line_exit_2(
    reference: tuple[Path, Path], tmp_path: Path, args: list[str], key: str
) -> None:
    f, _one = reference
    out = cli("campaign", str(f), *args, "--out", str(tmp_path / "o"))
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{key}:" in lines[0], lines
    assert not (tmp_path / "o").exists()


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_stops_a_local_cluster_campaign_without_a_traceback(tmp_path: Path) -> None:
    f = tiny(tmp_path / "tiny.yaml", samples=2000)  # far more than are done before the signal
    out = tmp_path / "int"
    proc = subprocess.Popen(
        [*EHPSS_HIL, "campaign", str(f), "--scheduler", "local:2", "--out", str(out), "--no-figures"],
        cwd=ROOT,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        preexec_fn=_default_sigint,  # a foreground command's Ctrl-C (see test_campaign.py)
    )
    wait_lines(out / JOURNAL_NAME, 2, proc)
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: to the campaign and its workers
    _stdout, stderr = proc.communicate(timeout=LIMIT_S)
    assert proc.returncode == 130, stderr
    assert b"Traceback" not in stderr and b"KeyboardInterrupt" not in stderr, stderr.decode()[-2000:]
    assert b"--resume" in stderr


def test_the_scheduler_gone_heartbeat_is_filtered_and_distributed_still_words_it_so() -> None:
    """A worker whose heartbeat finds the closing cluster's scheduler gone logs HEARTBEAT_LOST
    with a traceback (one Ctrl-C in ten printed it); the filter drops that record and no other.
    The text is distributed's: this fails when its Worker.heartbeat words it otherwise."""
    import inspect

    import distributed.worker

    assert HEARTBEAT_LOST in inspect.getsource(distributed.worker.Worker.heartbeat)
    f = SchedulerGoneFilter()

    def rec(msg: str) -> logging.LogRecord:
        return logging.LogRecord("distributed.worker", logging.ERROR, __file__, 1, msg, None, None)

    assert not f.filter(rec(HEARTBEAT_LOST + "."))
    assert f.filter(rec("Unexpected exception during heartbeat. Closing worker."))
    assert f.filter(rec("Compute Failed"))


def test_the_sync_cancel_name_error_is_filtered_while_distributed_has_it() -> None:
    """A Ctrl-C inside ``distributed.utils.sync`` before its coroutine bound ``future`` made
    tornado log a NameError from ``sync``'s ``cancel`` (one Ctrl-C in about thirty here). The
    filter drops that record and no other. This fails when distributed's ``sync`` changes (the
    filter may then be needed no more)."""
    import inspect

    import distributed.utils

    src = inspect.getsource(distributed.utils.sync)
    assert "def cancel() -> None:\n        if future is not None:" in src
    assert inspect.getsourcefile(distributed.utils.sync).endswith(SYNC_MODULE_TAIL)  # type: ignore[union-attr]

    def record_of(code: str, filename: str) -> logging.LogRecord:
        space: dict[str, object] = {}
        exec(compile(code, filename, "exec"), space)  # a cancel() compiled at that path
        try:
            space["cancel"]()  # type: ignore[operator]
        except Exception as exc:
            info = (type(exc), exc, exc.__traceback__)
        return logging.LogRecord("tornado.application", logging.ERROR, __file__, 1, "cb", None, info)

    f = SyncCancelFilter()
    unbound = "def cancel():\n    return future\n"
    assert not f.filter(record_of(unbound, "/x/" + SYNC_MODULE_TAIL))
    assert f.filter(record_of(unbound, "/x/elsewhere.py"))
    assert f.filter(record_of("def cancel():\n    raise ValueError('x')\n", "/x/" + SYNC_MODULE_TAIL))


def test_a_failing_run_is_retried_then_its_own_error_is_raised(
    reference: tuple[Path, Path],
) -> None:
    f, _one = reference
    camp = load_campaign(f)
    plans = plan_runs(camp)[:3]
    good = [RunTask(p.index, p.run_hash, p.scenario, camp.spec.modes) for p in plans[:2]]
    bad = RunTask(plans[2].index, plans[2].run_hash, plans[2].scenario, ("no-such-mode",))
    done: list[int] = []
    tally = Tally()
    with DaskExecutor("local:1", retries=2) as ex, pytest.raises(ModelError, match="no-such-mode"):
        ex.run([*good, bad], lambda rec: done.append(rec["index"]), tally)
    assert tally.retried == [bad.index, bad.index] and tally.lost_workers == []
    assert tally.text() == "0 workers lost, 2 runs retried"
    clean = Tally()
    with DaskExecutor("local:1") as ex:  # the same runs without the failing one: all finish
        ex.run(good, lambda rec: done.append(rec["index"]), clean)
    assert sorted(done[-2:]) == [p.index for p in plans[:2]] and clean.counts() == (0, 0)
