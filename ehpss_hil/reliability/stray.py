"""Stray datagrams on the embedded bus: anyone in the namespace may send to the group and port.

:func:`stray_trial` runs a bus logger, the controller and the emulator in a private namespace,
and while they run a sender (``python -m ehpss_hil.reliability.stray``) sends rounds of
datagrams that are no CAN frame (:data:`KINDS`: empty, text, a msgpack integer, a truncated
msgpack frame map, 60 kB of zeros). Every process must keep running, end with exit 0 and count
each of them as a rejected datagram (exit summary, log sidecar).
"""

from __future__ import annotations

import argparse
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
from can.interfaces.udp_multicast.utils import pack_message

from ..config import BusConfig
from .procs import PY, Trial, read_json_object


def _truncated_frame() -> bytes:
    """A python-can frame datagram cut short (an ID no process sends: no kernel filter drops
    it)."""
    import can

    return pack_message(
        can.Message(arbitration_id=0x555, data=bytes(8), is_extended_id=False, timestamp=1.0)
    )[:-5]


#: kind → datagram
KINDS: dict[str, bytes] = {
    "empty": b"",
    "text": b"hello",
    "msgpack int": msgpack.packb(7),
    "truncated frame map": _truncated_frame(),
    "60 kB": bytes(60_000),
}


def send_garbage(rounds: int, period_s: float, channel: str, port: int) -> int:
    """Send every kind ``rounds`` times, one round per ``period_s`` (s); returns datagrams sent."""
    n = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        for _ in range(rounds):
            for data in KINDS.values():
                s.sendto(data, (channel, port))
                n += 1
            time.sleep(period_s)
    return n


@dataclass
class StrayResult:
    """What each process did with the stray datagrams."""

    sent: int = 0
    #: process → alive right after the last datagram
    alive: dict[str, bool] = field(default_factory=dict)
    exits: dict[str, int | None] = field(default_factory=dict)
    #: process → rejected datagrams it reported (summary JSON or log sidecar; -1: none found)
    counted: dict[str, int] = field(default_factory=dict)
    error: str = ""

    @property
    def ok(self) -> bool:
        """All alive, exit 0, each counted exactly what was sent."""
        return (
            not self.error
            and self.sent > 0
            and all(self.alive.values())
            and all(v == 0 for v in self.exits.values())
            and all(v == self.sent for v in self.counted.values())
        )


#: the emulator's plant time limit (s): it is stopped long before, after the datagrams
EMULATOR_LIMIT_S = 120.0


def _total(d: dict[str, Any]) -> int:
    r = d.get("rejected_datagrams")
    return int(r.get("total", -1)) if isinstance(r, dict) else -1


def stray_trial(out: Path, rounds: int = 4) -> StrayResult:
    """Logger + controller + emulator with ``rounds`` rounds of :data:`KINDS` sent while they
    run; all three are then stopped with SIGTERM."""
    res = StrayResult()
    bus = BusConfig()
    with Trial(out) as t:
        procs = {"logger": t.logger("bus"), "controller": t.controller({})}
        # the plant runs until stopped: on a loaded host the sender may start late, and an
        # emulator that had already ended would read as a process the datagrams killed
        procs["emulator"] = t.emulator({}, "--duration", repr(EMULATOR_LIMIT_S))
        if not procs["controller"].wait_text("first sensor data", 60.0):
            res.error = "controller had no sensor data"
            return res
        snd = t.spawn(
            "stray",
            [
                PY,
                "-m",
                "ehpss_hil.reliability.stray",
                "--rounds",
                str(rounds),
                "--channel",
                bus.channel,
                "--port",
                str(bus.port),
            ],
        )
        snd.wait(30.0)
        try:
            res.sent = int(snd.text().split()[-1])
        except (ValueError, IndexError):
            res.error = f"sender: {snd.text()[-200:]}"
            return res
        time.sleep(0.2)
        res.alive = {n: c.popen.poll() is None for n, c in procs.items()}
        for n in ("emulator", "controller", "logger"):
            res.exits[n] = procs[n].terminate()
    res.counted = {
        "controller": _total(read_json_object(out / "controller.json")),
        "emulator": _total(read_json_object(out / "emulator.json")),
        "logger": _total(read_json_object(out / "bus.log.json")),
        "controller log": _total(read_json_object(out / "controller.log.json")),
    }
    return res


def main(argv: list[str] | None = None) -> int:
    """``python -m ehpss_hil.reliability.stray``: send the rounds, print ``sent N``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--period", type=float, default=0.1, help="s between rounds")
    p.add_argument("--channel", default=BusConfig().channel)
    p.add_argument("--port", type=int, default=BusConfig().port)
    a = p.parse_args(argv)
    print(f"sent {send_garbage(a.rounds, a.period, a.channel, a.port)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
