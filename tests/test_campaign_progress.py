"""The campaign's progress line off a terminal (a line per tenth of the runs or per 30 s, and at
once when a worker is lost), the tally of lost workers and retried runs, and the journal a
session that finished no run leaves behind (none)."""

from __future__ import annotations

import io
from pathlib import Path

from ehpss_hil.campaign.journal import JOURNAL_NAME, Journal
from ehpss_hil.campaign.progress import LOG_PERIOD_S, Progress
from ehpss_hil.campaign.session import prepare_out
from ehpss_hil.campaign.workers import Tally


class _Clock:
    """A clock the test moves by hand (s)."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_off_a_terminal_a_line_per_tenth_of_the_runs() -> None:
    stream, clock = io.StringIO(), _Clock()
    prog = Progress(1000, stream=stream, clock=clock)
    for _ in range(1000):
        clock.t += 0.001
        prog.step()
    prog.finish()
    lines = stream.getvalue().splitlines()
    assert [ln.split()[1] for ln in lines] == [f"{n}/1000" for n in range(100, 1001, 100)]
    assert "ETA" in lines[0] and "lost" not in lines[-1]


def test_off_a_terminal_a_slow_campaign_prints_every_30_s_and_a_lost_worker_at_once() -> None:
    stream, clock = io.StringIO(), _Clock()
    prog = Progress(1000, already=10, stream=stream, clock=clock)
    clock.t = LOG_PERIOD_S + 1.0
    prog.step()  # 11/1000: no tenth crossed, but 31 s since the start
    prog.step()  # not due
    prog.tally.lost("tcp://10.0.0.2:4000", [14, 15])
    prog.step()  # a worker lost: at once
    lines = stream.getvalue().splitlines()
    assert [ln.split()[1] for ln in lines] == ["11/1000", "13/1000"]
    assert lines[-1].endswith(", 1 worker lost, 2 runs retried")
    assert lines[0].startswith("campaign: 11/1000 runs (1.1 %), 0.03 runs/s, ETA")  # 1 run in 31 s


def test_the_tally_names_the_lost_workers_and_the_retried_runs() -> None:
    tally = Tally()
    assert tally.text() == "" and tally.detail() == ""
    tally.lost("tcp://a:1", [7, 3])
    tally.retry(9)
    tally.lost("tcp://b:2", [])
    assert tally.text() == "2 workers lost, 3 runs retried"
    assert tally.detail() == "2 workers lost (tcp://a:1, tcp://b:2), 3 runs retried (runs 3, 7, 9)"


def test_a_journal_no_run_was_written_to_is_removed_and_the_directory_reused(tmp_path: Path) -> None:
    out = tmp_path / "o"
    with Journal(prepare_out(out, resume=False)):
        pass  # the scheduler went away before the first run finished
    assert not (out / JOURNAL_NAME).exists()
    with Journal(prepare_out(out, resume=False)) as j:  # no --resume needed
        j.append({"run_hash": "x", "index": 0, "metrics": {}})
    assert (out / JOURNAL_NAME).read_bytes().count(b"\n") == 1
    (out / "runs.jsonl").write_bytes(b"")  # an empty journal of an older version
    prepare_out(out, resume=False)
