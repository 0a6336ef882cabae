"""``ehpss-hil log -i INTERFACE -c CHANNEL -o FILE``: a CAN logger on any python-can bus.

Writes ``FILE`` — candump ``-L`` (rotated by size), or BLF / MF4 (``--log-format``, or the
suffix ``.blf`` / ``.mf4``; not rotated; MF4 needs the ``mf4`` extra) — and ``FILE.json``
(sidecar). Stops on SIGINT/SIGTERM or after
``--duration`` seconds, flushes everything and prints the counts (exit 0). A bus that cannot be
opened exits 3 with the reason, a log that cannot be written (read-only or full folder) exits 2
with the reason and leaves no file behind. An existing ``FILE`` (or ``FILE.json``, ``FILE.1`` …)
that is no log of ours is refused the same way (exit 2, nothing touched) unless ``--overwrite``;
rotation removes only files of this log. A full disk while logging: lines are dropped and
counted (sidecar, final line), the logger goes on and exits 0. Datagrams on a udp_multicast
group that are no frame are counted and skipped.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from pathlib import Path
from types import FrameType

import can

from ..bus import datagram_rejects, open_listener_bus
from ..canlog import CandumpLogger
from ..canlog.formats import add_log_format_argument
from ..errors import OutputError

NAME = "log"

_CLOCKS = {
    "socketcan": "kernel receive timestamp (SO_TIMESTAMP), wall clock, s since the Unix epoch",
    "udp_multicast": "receive socket timestamp (SO_TIMESTAMPNS), wall clock, s since the Unix epoch",
    "virtual": "sender's msg.timestamp (time.time() unless the sender set it), s",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``ehpss-hil log``."""
    p.add_argument(
        "-i",
        "--interface",
        required=True,
        help="python-can interface: udp_multicast, socketcan, virtual, or any other",
    )
    p.add_argument("-c", "--channel", required=True, help="channel (vcan0, can0, 239.74.163.2, …)")
    p.add_argument(
        "-o", "--output", required=True, type=Path, help="log file (candump -L; *.blf: BLF, *.mf4: MF4)"
    )
    add_log_format_argument(p)
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a file at --output that is no log of ours (and its numbered files)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=0.0,
        metavar="S",
        help="stop after S seconds (default: until SIGINT/SIGTERM)",
    )
    p.add_argument(
        "--iface",
        default="",
        help="interface name written in each line (default: the channel for socketcan, else can0)",
    )
    p.add_argument("--port", type=int, default=None, help="udp_multicast port (default: config's)")
    p.add_argument("--max-bytes", type=int, default=256 * 2**20, help="rotate above this size (candump only)")
    p.add_argument("--backups", type=int, default=5, help="rotated files kept (0: never rotate)")
    p.add_argument("--queue-lines", type=int, default=200_000, help="writer queue bound (frames)")


class _StopFlag:
    """Set by SIGINT/SIGTERM; the handler only flips a flag (the loop does the shutdown)."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal_name = ""

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        self.signal_name = signal.Signals(signum).name
        self.event.set()


def record(bus: can.BusABC, logger: CandumpLogger, stop: threading.Event, duration_s: float = 0.0) -> int:
    """Receive frames into ``logger`` until ``stop`` is set or ``duration_s`` (s) elapsed (0: no
    limit), then log what is already queued. Returns the number of frames received."""
    deadline = time.monotonic() + duration_s if duration_s > 0 else None
    n = 0
    while not stop.is_set():
        timeout = 0.1
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            timeout = min(timeout, left)
        msg = bus.recv(timeout=timeout)
        if msg is not None:
            logger.log(msg)
            n += 1
    return n + drain(bus, logger)


def drain(bus: can.BusABC, logger: CandumpLogger, limit: int = 1_000_000) -> int:
    """Log what the bus had already received when the stop came (non-blocking, bounded)."""
    n = 0
    while n < limit:
        msg = bus.recv(timeout=0.0)
        if msg is None:
            return n
        logger.log(msg)
        n += 1
    return n


def run(args: argparse.Namespace) -> int:
    """Open the bus, log until stopped, print counts."""
    bus = open_listener_bus(args.interface, args.channel, args.port)
    iface = args.iface or (args.channel if args.interface == "socketcan" else "can0")
    meta = {
        "bus": {"interface": args.interface, "channel": args.channel},
        "clock": _CLOCKS.get(args.interface, "python-can receive timestamp (s)"),
        "process": {"command": "ehpss-hil log", "argv": sys.argv[1:]},
    }
    stop = _StopFlag()
    old = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            logger = CandumpLogger(
                args.output,
                iface=iface,
                max_bytes=args.max_bytes,
                backups=args.backups,
                queue_lines=args.queue_lines,
                sidecar=meta,
                overwrite=args.overwrite,
                fmt=args.log_format,
            )
        except OutputError:
            raise
        except OSError as exc:
            raise OutputError(f"{args.output}: cannot write the log: {exc.strerror or exc}") from exc
        try:
            print(
                f"logging {args.interface}:{args.channel} -> {args.output} (Ctrl-C to stop)",
                file=sys.stderr,
                flush=True,
            )
            received = record(bus, logger, stop.event, args.duration)
        finally:
            rejects = datagram_rejects(bus)
            if rejects is not None:
                logger.note("rejected_datagrams", rejects.as_dict())
            summary = logger.close()
    finally:
        bus.shutdown()
        for s, h in old.items():
            signal.signal(s, h)
    why = f" on {stop.signal_name}" if stop.signal_name else ""
    bad = f"; {rejects.total} datagrams rejected ({rejects.text()})" if rejects else ""
    print(f"stopped{why}: {received} frames received{bad}; {summary}", flush=True)
    return 0
