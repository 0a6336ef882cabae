"""``ehpss-hil monitor``: a listen-only node that decodes the bus with the DBC and shows it live
in a local web page (or, with ``--tui``, in the terminal). docs/monitor.md.

It never transmits, except one FAULT_INJECT frame per click when started with
``--allow-inject``. ``--config`` takes the controller's config: its bus, DBC, ID base and its
reference (so x_d and y_m are drawn); ``--netns`` listens inside another network namespace (an
``ehpss-hil run``'s private bus) while the page stays on this host's 127.0.0.1.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from ..bus import open_listener_bus
from ..config import BusConfig, ControllerConfig, load_controller_config
from ..errors import ConfigError
from ..extras import require

NAME = "monitor"
#: the page's default TCP port
DEFAULT_PORT = 8050
#: the page server's nice value: CFS gives a nice-10 process about a tenth of a nice-0 one's
#: share when both want the CPU (a controller at --rt-priority is never preempted by it at all)
MONITOR_NICE = 10


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``ehpss-hil monitor``."""
    p.add_argument("-i", "--interface", help="python-can interface (default: the config's, udp_multicast)")
    p.add_argument("-c", "--channel", help="channel: vcan0, can0, a multicast group (default: the config's)")
    p.add_argument("--bus-port", type=int, help="udp_multicast port (default: the config's)")
    p.add_argument(
        "--config",
        type=Path,
        help="controller config (configs/controller.yaml, a run's controller.yaml): bus, DBC, "
        "ID base, and the reference for x_d/y_m",
    )
    p.add_argument(
        "--netns",
        metavar="PATH",
        help="listen inside this network namespace (/proc/PID/ns/net of a run's namespace; root)",
    )
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help="page port (0: any free one)")
    p.add_argument("--host", default="127.0.0.1", help="page address (default 127.0.0.1: this host only)")
    p.add_argument(
        "--allow-host",
        action="append",
        default=[],
        metavar="NAME",
        help="a further name the page may be requested by (Host header); repeatable",
    )
    p.add_argument(
        "--allow-inject",
        action="store_true",
        help="show fault-injection buttons that send FAULT_INJECT frames (bench only)",
    )
    p.add_argument(
        "--capture-dir",
        type=Path,
        default=Path("monitor-captures"),
        metavar="DIR",
        help="where the page's triggered captures (candump log + CSV) are written "
        "(default ./monitor-captures, made on the first capture)",
    )
    p.add_argument("--refresh-hz", type=float, default=20.0, help="page updates per second (default 20)")
    p.add_argument("--tui", action="store_true", help="show the figures in this terminal instead of a page")
    p.add_argument("--duration", type=float, default=0.0, metavar="S", help="--tui: stop after S seconds")


def _config(args: argparse.Namespace) -> ControllerConfig | None:
    return load_controller_config(args.config) if args.config is not None else None


def _bus(args: argparse.Namespace, cfg: ControllerConfig | None) -> BusConfig:
    base = cfg.bus if cfg is not None else BusConfig()
    try:
        return BusConfig(
            interface=args.interface or base.interface,
            channel=args.channel or base.channel,
            bitrate=base.bitrate,
            port=args.bus_port if args.bus_port is not None else base.port,
        )
    except ConfigError as exc:
        raise ConfigError("command line", exc.key_path, exc.reason) from exc


def run(args: argparse.Namespace) -> int:
    """Listen, decode, serve (or print) until stopped."""
    if not 0.5 <= args.refresh_hz <= 100.0:
        raise ConfigError("command line", "--refresh-hz", f"expected 0.5 … 100, got {args.refresh_hz:g}")
    if not 0 <= args.port <= 65535:
        raise ConfigError("command line", "--port", f"expected 0 … 65535, got {args.port}")
    if not args.tui:
        require("monitor", "the monitor's web page (or use --tui)")
    cfg = _config(args)
    bus = _bus(args, cfg)
    from ..monitor.build import build_listener

    listener = build_listener(
        lambda: open_listener_bus(bus.interface, bus.channel, bus.port),
        cfg,
        args.config,
        bitrate=bus.bitrate,
        netns=args.netns,
        allow_inject=args.allow_inject,
        capture_dir=args.capture_dir,
    )
    where = f"{bus.interface}:{bus.channel}" + (f" in {args.netns}" if args.netns else "")
    listener.start()
    try:
        if args.tui:
            from ..monitor.tui import run_tui

            run_tui(listener, where, args.duration)
        else:
            from ..monitor.server import serve

            if args.host not in ("127.0.0.1", "localhost", "::1"):
                print(f"warning: the page is reachable from other hosts on {args.host}", file=sys.stderr)
            print(
                f"listening on {where}" + (" (fault injection ON)" if args.allow_inject else ""), flush=True
            )
            os.nice(MONITOR_NICE)  # the controller's CPU first (docs/monitor.md)
            serve(
                listener,
                args.host,
                args.port,
                args.refresh_hz,
                title=f"ehpss-hil monitor · {where}",
                extra_hosts=tuple(args.allow_host),
            )
    finally:
        listener.stop()
    if listener.error is not None:
        raise listener.error
    return 0
