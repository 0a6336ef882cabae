"""``ehpss-hil controller``: the controller daemon (realtime or lockstep) on the configured bus."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from ..canlog.formats import add_process_log_arguments
from ..control.registry import DAEMON_MODES
from ..daemon import DaemonArgs, run_daemon
from ..runtime.loop_options import LoopOptions

NAME = "controller"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-c", "--config", required=True, type=Path, help="controller.yaml")
    p.add_argument(
        "--interface", choices=("udp_multicast", "socketcan", "virtual"), help="override bus.interface"
    )
    p.add_argument("--channel", help="override bus.channel (vcan0, can0, a 239.x.y.z group)")
    p.add_argument("--mode", choices=DAEMON_MODES, help="control law (overrides mode)")
    p.add_argument("--rate", type=float, help="cycle rate (Hz), overrides rate_hz")
    p.add_argument("--rt-priority", type=int, help="SCHED_FIFO priority 1..99 (0 = none)")
    p.add_argument("--cpu", type=int, help="pin to this CPU")
    add_process_log_arguments(p)
    p.add_argument("--duration", type=float, help="stop after this many seconds (cycles)")
    p.add_argument(
        "--lockstep",
        action="store_true",
        help="answer each received sensor pair instead of running on a clock",
    )
    p.add_argument(
        "--lockstep-idle",
        type=float,
        metavar="SECONDS",
        help="lockstep: end after this long without frames once the peer has started "
        f"(default {LoopOptions().lockstep_idle_s:g} s)",
    )
    p.add_argument(
        "--sensor-age-us",
        type=float,
        help="phase lock: run each cycle this long after the sensor frame arrives "
        "(µs; default 0 = free-running grid)",
    )
    p.add_argument("--summary-json", type=Path, help="write the final counters as JSON here")
    p.add_argument("--controller-factory", help=argparse.SUPPRESS)  # module:function (tests)
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        stream=sys.stderr,
        format="ehpss-hil controller: %(levelname)s: %(message)s",
    )
    return run_daemon(
        DaemonArgs(
            config=args.config,
            interface=args.interface,
            channel=args.channel,
            mode=args.mode,
            rate_hz=args.rate,
            rt_priority=args.rt_priority,
            cpu=args.cpu,
            log=args.log,
            overwrite_log=args.overwrite,
            log_format=args.log_format,
            duration_s=args.duration,
            lockstep=args.lockstep,
            lockstep_idle_s=args.lockstep_idle,
            summary_json=args.summary_json,
            controller_factory=args.controller_factory,
            sensor_age_us=args.sensor_age_us,
        )
    )
