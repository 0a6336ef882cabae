"""A process killed with SIGTERM whose handler calls ``close()`` leaves a complete log."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import can

from ehpss_hil.canlog import read_sidecar

CHILD = textwrap.dedent("""
    import signal, sys
    from ehpss_hil.canlog import CandumpLogger
    from ehpss_hil.codec import FrameCodec

    log = CandumpLogger(sys.argv[1], iface="vcan0", max_bytes=200_000, backups=100)

    def on_term(signum, frame):
        s = log.close()          # straight from the handler: the harsh case
        log.close()              # idempotent
        print(s.written, s.dropped, flush=True)
        sys.exit(0)

    signal.signal(signal.SIGTERM, on_term)
    codec = FrameCodec()
    k = 0
    print("ready", flush=True)
    while True:
        for name in ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD"):
            log.log(codec.encode(name, {}, timestamp_s=1e9 + k * 1e-3))
        k += 1
""")


def _wait_for_file(path: Path, proc: subprocess.Popen[str]) -> None:
    """Wait (no time limit asserted) until ``path`` exists while the child still runs."""
    while not path.exists():
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(0.01)


def test_sigterm_leaves_complete_log(tmp_path: Path) -> None:
    log = tmp_path / "run.log"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(log)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    _wait_for_file(tmp_path / "run.log.5", proc)  # >= 5 rotations: > 20 000 lines written
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    written, dropped = (int(x) for x in out.split())
    side = read_sidecar(log)
    assert side is not None and side["status"] == "closed"
    assert side["counts"]["written"] == written and side["counts"]["dropped"] == dropped
    total = 0
    for entry in side["files"]:
        f = tmp_path / entry["name"]
        raw = f.read_bytes()
        assert raw.endswith(b"\n")  # no partial line anywhere
        with can.CanutilsLogReader(f) as reader:
            n = sum(1 for _ in reader)
        assert n == entry["lines"]
        total += n
    assert total == written > 20_000
