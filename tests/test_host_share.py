"""The host share a test takes (tests/_host_share.py): shared holders together, an exclusive one
alone, and a waiting exclusive taker lets no new shared taker in. flock locks taken through
different opens conflict within one process too, so the takers here are threads."""

from __future__ import annotations

import fcntl
import threading
import time
from pathlib import Path

from _host_share import host_share

#: a wait that ends well inside the test (s)
SHORT_S = 0.3


def _files(tmp_path: Path) -> tuple[Path, Path]:
    return tmp_path / "host.lock", tmp_path / "gate.lock"


def test_shared_takers_hold_together_an_exclusive_one_does_not(tmp_path: Path) -> None:
    host, gate = _files(tmp_path)
    with host_share(False, host, gate, SHORT_S) as a:
        with host_share(False, host, gate, SHORT_S) as b:
            assert a and b
        with host_share(True, host, gate, SHORT_S) as c:
            assert not c  # a shared holder is running
    with host_share(True, host, gate, SHORT_S) as d:
        assert d
        with host_share(False, host, gate, SHORT_S) as e:
            assert not e
        with host_share(True, host, gate, SHORT_S) as f:
            assert not f


def test_a_waiting_exclusive_taker_lets_no_new_shared_taker_in(tmp_path: Path) -> None:
    host, gate = _files(tmp_path)
    got: list[bool] = []
    with host_share(False, host, gate, SHORT_S) as first:
        assert first

        def exclusive() -> None:
            with host_share(True, host, gate, 30.0) as had:
                got.append(had)

        t = threading.Thread(target=exclusive)
        t.start()
        deadline = time.monotonic() + 30.0
        while not _gate_closed(gate) and time.monotonic() < deadline:
            time.sleep(0.01)  # until the exclusive taker holds the gate and polls the host lock
        with host_share(False, host, gate, SHORT_S) as late:
            assert not late  # the host is only shared, but an exclusive taker is waiting
        assert got == []
    t.join(30.0)
    assert got == [True]


def _gate_closed(gate: Path) -> bool:
    with gate.open("a") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        return False
