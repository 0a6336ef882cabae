"""On vcan0, with the real can-utils: ``canplayer`` plays our log, and ``candump -L`` and our
logger (``ehpss-hil log``'s ``record`` on the project's socketcan bus) record it — line for
line the same text (timestamps aside).

Marked ``socketcan``: run inside ``../shared/tools/vcan-vm/run`` (this kernel has no SocketCAN).
"""

from __future__ import annotations

import shutil
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import can
import pytest

from ehpss_hil.bus import open_bus
from ehpss_hil.canlog import CandumpLogger
from ehpss_hil.codec import FrameCodec
from ehpss_hil.commands import log as log_cmd
from ehpss_hil.config import BusConfig


def _af_can() -> bool:
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (OSError, AttributeError):
        return False
    return True


pytestmark = [
    pytest.mark.socketcan,
    pytest.mark.skipif(not _af_can(), reason="no SocketCAN: run via ../shared/tools/vcan-vm/run"),
    pytest.mark.skipif(
        shutil.which("canplayer") is None or shutil.which("candump") is None,
        reason="can-utils (candump, canplayer) not installed",
    ),
]


def _frames() -> list[can.Message]:
    codec = FrameCodec()
    out = []
    for k in range(30):
        t = 1_700_000_000.0 + k * 1e-3
        out.append(codec.encode("SENSOR_POS", {"Position": 1e-5 * k}, timestamp_s=t))
        out.append(
            codec.encode("VALVE_CMD", {"CurrentSetpoint": 1e-3 * k, "CycleCount": k}, timestamp_s=t + 2e-4)
        )
    out.append(
        can.Message(timestamp=t + 5e-4, arbitration_id=0x1ABCDE0, is_extended_id=True, data=b"\x01\x02\x03")
    )
    out.append(can.Message(timestamp=t + 6e-4, arbitration_id=0x7FF, is_extended_id=False, data=b""))
    return out


def _body(line: str) -> str:
    """``iface ID#DATA`` of a candump -L line (the timestamp dropped)."""
    return line.split(" ", 1)[1].strip()


def test_canplayer_candump_and_our_logger_agree(tmp_path: Path) -> None:
    ours = tmp_path / "ours.log"
    with CandumpLogger(ours, iface="vcan0") as lg:
        for m in _frames():
            lg.log(m)
    dump = subprocess.Popen(["candump", "-L", "vcan0"], stdout=subprocess.PIPE, text=True)
    stop = threading.Event()
    with open_bus(BusConfig(interface="socketcan", channel="vcan0")) as bus:
        rec = CandumpLogger(tmp_path / "rec.log", iface="vcan0")
        th = threading.Thread(target=log_cmd.record, args=(bus, rec, stop))
        th.start()
        time.sleep(0.5)  # let candump open its socket (a wait, not a measurement)
        subprocess.run(["canplayer", "-I", str(ours)], check=True, timeout=120)
        time.sleep(0.5)
        stop.set()  # record() then drains what the socket already holds
        th.join()
        rec.close()
    dump.send_signal(signal.SIGINT)
    dumped, _ = dump.communicate(timeout=60)
    expected = [_body(x) for x in ours.read_text().splitlines()]
    assert [_body(x) for x in dumped.splitlines()] == expected
    assert [_body(x) for x in (tmp_path / "rec.log").read_text().splitlines()] == expected


def test_replay_of_a_candump_recording_is_exact(tmp_path: Path) -> None:
    """A lockstep run (3 % sensor loss) played on vcan0 by ``canplayer`` and recorded by
    ``candump -L`` (can-utils: its own timestamps and file order, no sidecar) replays bit for
    bit with the scenario and mode given."""
    from ehpss_hil import PROJECT_ROOT
    from ehpss_hil.replay.engine import replay_log
    from ehpss_hil.scenario import load_scenario
    from ehpss_hil.sim.samplelog import write_lockstep_log

    src = PROJECT_ROOT / "scenarios" / "extra" / "unseen-frameloss2pct.yaml"
    scenario = tmp_path / "scenario.yaml"
    text = "".join(
        line
        for line in src.read_text().splitlines(keepends=True)
        if "t_s: 1.5" not in line and "t_s: 2.5" not in line
    )
    scenario.write_text(
        text.replace("duration_s: 3.5", "duration_s: 0.6").replace(
            "frame_loss: 0.02", "frame_loss: 0.0\nsensor_frame_loss: 0.03"
        )
    )
    run = write_lockstep_log(load_scenario(scenario), "mmac", tmp_path / "run.log")
    rec = tmp_path / "candump.log"
    with open(rec, "w") as out:
        dump = subprocess.Popen(["candump", "-L", "vcan0"], stdout=out)
        time.sleep(0.5)  # let candump open its socket (a wait, not a measurement)
        subprocess.run(["canplayer", "-I", str(run)], check=True, timeout=300)
        time.sleep(0.5)
        dump.send_signal(signal.SIGINT)
        dump.wait(timeout=60)
    res = replay_log(rec, mode="mmac", scenario=scenario)
    assert res.cycles == 600 and res.identical, (res.divergent, res.first)
