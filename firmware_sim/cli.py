"""``firmware-sim``: the plant emulator process.

``firmware-sim -c configs/emulator.yaml [--interface I --channel C] [--scenario S] [--rate HZ]
[--mode realtime|lockstep] [--truth] [--log FILE [--log-format candump|blf|mf4]] [--duration S]``

Realtime, a scenario given with ``--scenario`` ends at its duration (a run); the config's own
``scenario:`` runs until SIGTERM/SIGINT (the stand-in valve's background); ``--duration`` sets
the length either way. Lockstep ends after the scenario's duration (or ``--duration``).

Exit codes: 0 (normal end, SIGTERM/SIGINT), 1 (lockstep peer stopped answering, other errors),
2 (bad config: the message names file and key path), 3 (bus unavailable).
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path

from ehpss_hil.blas import limit_blas_threads
from ehpss_hil.bus import open_bus
from ehpss_hil.canlog.formats import add_process_log_arguments
from ehpss_hil.codec import FrameCodec
from ehpss_hil.config import EmulatorConfig, apply_overrides, load_emulator_config
from ehpss_hil.errors import ConfigError, run_console
from ehpss_hil.physics.load import load_params
from ehpss_hil.runtime.frameio import FrameIO, open_process_logger, process_codec
from ehpss_hil.runtime.rt import apply_rt_options, freeze_gc
from ehpss_hil.runtime.signals import install_stop_handlers, restore_handlers
from ehpss_hil.runtime.stats import publish_summary, rejects_text
from ehpss_hil.scenario import Scenario, load_scenario

from .process import OWN_FRAMES, EmulatorOptions, EmulatorProcess
from .wiring import REVERSIBLE, make_emulation

log = logging.getLogger("firmware_sim")
CLOCK_NOTE = (
    "wall clock (time.time()) at send for frames sent; the bus's receive timestamp "
    "(kernel SO_TIMESTAMPNS on udp_multicast/socketcan) for frames received"
)


def build_parser() -> argparse.ArgumentParser:
    """The ``firmware-sim`` argument parser."""
    p = argparse.ArgumentParser(prog="firmware-sim", description="EHPSS plant emulator on CAN.")
    p.add_argument("-c", "--config", required=True, type=Path, help="emulator.yaml")
    p.add_argument(
        "--interface", choices=("udp_multicast", "socketcan", "virtual"), help="override bus.interface"
    )
    p.add_argument("--channel", help="override bus.channel (vcan0, a 239.x.y.z group, ...)")
    p.add_argument(
        "--scenario",
        type=Path,
        help="override the scenario file; the run then ends at the scenario's duration "
        "(without it, realtime runs until SIGTERM)",
    )
    p.add_argument("--rate", type=float, help="period rate (Hz), overrides rate_hz")
    p.add_argument("--mode", choices=("realtime", "lockstep"), help="override mode")
    p.add_argument("--truth", action="store_true", help="send PLANT_TRUTH/PLANT_FAULTS (bench)")
    p.add_argument("--fault-inject", action="store_true", help="accept FAULT_INJECT frames")
    p.add_argument("--rt-priority", type=int, help="SCHED_FIFO priority 1..99 (0 = none)")
    p.add_argument("--cpu", type=int, help="pin to this CPU")
    add_process_log_arguments(p)
    p.add_argument(
        "--duration",
        type=float,
        help="stop after this many seconds of plant time (default: the --scenario's duration; "
        "realtime with the config's scenario: until SIGTERM)",
    )
    p.add_argument(
        "--lockstep-timeout",
        type=float,
        default=5.0,
        help="lockstep: give up when no VALVE_CMD arrives for this long (s)",
    )
    p.add_argument(
        "--reverse",
        action="append",
        choices=REVERSIBLE,
        help="impersonate a miswired valve: the coil current, the spool LVDT or the position "
        "sensor reversed (bring-up tests; repeatable)",
    )
    p.add_argument("--summary-json", type=Path, help="write the final counters as JSON here")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    return p


def _resolve(args: argparse.Namespace) -> tuple[EmulatorConfig, Scenario]:
    """Config + command-line overrides + scenario, validated (raises ConfigError)."""
    cfg = load_emulator_config(args.config)
    src = str(args.config)
    bus = cfg.bus
    bus, rate, rt = apply_overrides(
        src,
        bus,
        cfg.rate_hz,
        cfg.rt,
        interface=args.interface,
        channel=args.channel,
        rate=args.rate,
        rt_priority=args.rt_priority,
        cpu=args.cpu,
    )
    cfg = replace(
        cfg,
        bus=bus,
        rate_hz=rate,
        mode=args.mode or cfg.mode,
        rt=rt,
        truth=cfg.truth or args.truth,
        fault_inject=cfg.fault_inject or args.fault_inject,
    )
    path = args.scenario or (Path(cfg.scenario) if cfg.scenario else None)
    scenario = load_scenario(path) if path is not None else Scenario(name="default", duration_s=3600.0)
    if abs(scenario.sample_time_s * rate - 1.0) > 1e-9:
        scenario = replace(scenario, sample_time_s=1.0 / rate)
    if args.duration is not None and args.duration <= 0.0:
        raise ConfigError(src, "--duration", "must be > 0 s")
    return cfg, scenario


def format_summary(s: dict[str, object]) -> str:
    """The counters printed at exit."""
    st = s["stats"]
    assert isinstance(st, dict)
    lat = st["lateness_s"]
    lines = [
        f"firmware-sim: periods {s['periods']}",
        f"  frames sent: {s['frames_sent']} (tx errors {s['tx_errors']})",
        f"  frames received: {s['frames_received']}; by verdict {s['received_by_verdict']}",
        f"  datagrams rejected (not a frame): {rejects_text(s)}",
        f"  commands accepted {s['commands_accepted']}, command timeouts "
        f"{s['command_timeouts']}, lost sensor/command frames {s['lost_sensor_frames']}/"
        f"{s['lost_command_frames']}, clipped values {s['clipped_values']}",
        f"  overruns {st['overruns']} (skipped periods {st['skipped']}), wake-up lateness "
        f"p50 {lat['p50'] * 1e6:.1f} µs p99 {lat['p99'] * 1e6:.1f} µs "
        f"max {lat['max'] * 1e6:.1f} µs, compute p99 "
        f"{st['compute_s']['p99'] * 1e6:.1f} µs",
    ]
    if s.get("plant_failure"):
        lines.append(f"  plant failure (fail-safe): {s['plant_failure']}")
    return "\n".join(lines)


def format_canopen_summary(s: dict[str, object]) -> str:
    """The counters printed at exit with ``protocol: cia408``."""
    st = s["stats"]
    assert isinstance(st, dict)
    lat = st["lateness_s"]
    nodes = s["nodes"]
    assert isinstance(nodes, dict)
    lines = [
        f"firmware-sim (cia408): periods {s['periods']}, SYNCs {s['syncs']}, valve {s['valve_state']}",
        f"  frames sent: {s['frames_sent']} (tx errors {s['tx_errors']})",
        f"  frames received: {s['frames_received']} (for no node: {s['unused_frames']})",
        *(f"  {name}: {', '.join(f'{k} {v}' for k, v in n.items())}" for name, n in nodes.items()),
        f"  overruns {st['overruns']} (skipped periods {st['skipped']}), wake-up lateness "
        f"p50 {lat['p50'] * 1e6:.1f} µs p99 {lat['p99'] * 1e6:.1f} µs, compute p99 "
        f"{st['compute_s']['p99'] * 1e6:.1f} µs",
    ]
    if s.get("plant_failure"):
        lines.append(f"  plant failure (valve FAULT, EMCY): {s['plant_failure']}")
    return "\n".join(lines)


def _sidecar(args: argparse.Namespace, cfg: EmulatorConfig, scenario: Scenario) -> dict[str, object]:
    """The log sidecar's description of this emulator run (both protocols)."""
    return {
        "tool": "firmware-sim",
        "config": asdict(cfg),
        "config_path": str(args.config),
        "dbc": cfg.dbc or None,
        "scenario": asdict(scenario),
        "scenario_name": scenario.name,
        "rate_hz": cfg.rate_hz,
        "clock": CLOCK_NOTE,
        "bus": f"{cfg.bus.interface}:{cfg.bus.channel}",
        "mode": cfg.mode,
        "protocol": cfg.protocol,
    }


def realtime_periods(args: argparse.Namespace, rate_hz: float, scenario: Scenario) -> int | None:
    """Periods a realtime run lasts: ``--duration``; else the scenario's when it was given on the
    command line; None (until SIGTERM) for the config's own scenario."""
    if args.duration is not None:
        return round(args.duration * rate_hz)
    return scenario.n_samples if args.scenario is not None else None


def _truth_codec(cfg: EmulatorConfig, src: str) -> FrameCodec:
    """The native codec whose PLANT_TRUTH the CANopen emulator sends (``truth``); an ID that is
    one of the nodes' COB-IDs is a ConfigError naming ``ids.id_base``."""
    from ehpss_hil.protocol.cia408 import cobid

    codec = FrameCodec(cfg.dbc or None, id_base=cfg.ids.id_base)
    can_id = codec.can_id("PLANT_TRUTH")
    service, node = cobid.classify(can_id)
    if service in ("NMT", "SYNC") or node in (cfg.nodes.valve_node, cfg.nodes.encoder_node):
        raise ConfigError(
            src, "ids.id_base", f"PLANT_TRUTH at 0x{can_id:03X} is the {service} of node {node}"
        )
    return codec


def run_canopen(args: argparse.Namespace, cfg: EmulatorConfig, scenario: Scenario) -> int:
    """``protocol: cia408``: the plant behind an emulated CiA 408 valve and CiA 406 encoder;
    1 when the plant failed (the valve went to FAULT and the run went on), else 0."""
    from ehpss_hil.protocol.cia408.check import check_nodes
    from ehpss_hil.runtime.rawio import RawFrameIO

    from .canopen_process import CanopenEmulatorProcess, CanopenOptions, build_nodes

    params = load_params(cfg.params or None)
    valve_od, encoder_od = check_nodes(cfg.nodes, str(args.config))
    emu = make_emulation(params, scenario, args.reverse)
    logging.getLogger("canopen").setLevel(logging.WARNING)  # its SDO server logs every transfer
    bus = open_bus(cfg.bus)
    logger = open_process_logger(
        args.log,
        cfg.log,
        cfg.bus,
        bus,
        str(args.config),
        _sidecar(args, cfg, scenario),
        args.overwrite,
        args.log_format,
    )
    io = RawFrameIO(bus, logger)
    valve, encoder = build_nodes(cfg.nodes, valve_od, encoder_od, io, params.plant.spool_stroke_m)
    truth = _truth_codec(cfg, str(args.config)) if cfg.truth else None
    proc = CanopenEmulatorProcess(emu, io, valve, encoder, CanopenOptions(truth=truth))
    stop, previous = install_stop_handlers()
    try:
        limit_blas_threads(1)
        apply_rt_options(cfg.rt)
        freeze_gc(cfg.rt.gc_freeze)
        log.info(
            "cia408: valve node %d, encoder node %d on %s:%s at %g Hz, scenario %s",
            cfg.nodes.valve_node,
            cfg.nodes.encoder_node,
            cfg.bus.interface,
            cfg.bus.channel,
            cfg.rate_hz,
            scenario.name,
        )
        proc.run_realtime(stop, realtime_periods(args, cfg.rate_hz, scenario))
    finally:
        restore_handlers(previous)
        io.close()
        bus.shutdown()
    publish_summary(format_canopen_summary, proc.summary(), args.summary_json)
    return 1 if proc.plant_failure else 0


def run(args: argparse.Namespace) -> int:
    """Configure, run until the end/stop signal, print the counters; returns the exit code."""
    cfg, scenario = _resolve(args)
    if cfg.protocol == "cia408":
        return run_canopen(args, cfg, scenario)
    if scenario.device_faults():
        log.warning("device_fault events are read with protocol cia408 only; ignored (%s)", cfg.protocol)
    params = load_params(cfg.params or None)
    codec = process_codec(
        cfg.dbc,
        cfg.ids,
        str(args.config),
        cfg.protocol,
        cfg.dbc_map,
        stroke_current_a=params.plant.stroke_current_a,
    )
    emu = make_emulation(params, scenario, args.reverse)
    bus = open_bus(cfg.bus)
    try:  # until the run's own shutdown takes over: the bus (and the log) closed on any error
        logger = open_process_logger(
            args.log,
            cfg.log,
            cfg.bus,
            bus,
            str(args.config),
            sidecar=_sidecar(args, cfg, scenario),
            overwrite=args.overwrite,
            fmt=args.log_format,
        )
    except BaseException:
        bus.shutdown()
        raise
    io = FrameIO(bus, codec, OWN_FRAMES, logger)
    try:
        proc = EmulatorProcess(
            emu,
            io,
            EmulatorOptions(
                command_timeout_s=cfg.command_timeout_s,
                truth=cfg.truth,
                fault_inject=cfg.fault_inject,
                heartbeat_rate_hz=cfg.heartbeat_rate_hz,
                lockstep_timeout_s=args.lockstep_timeout,
            ),
        )
    except BaseException:
        io.close()
        bus.shutdown()
        raise
    stop, previous = install_stop_handlers()
    ok = True
    try:
        limit_blas_threads(1)  # idle OpenBLAS workers spin and steal the loop's CPU
        apply_rt_options(cfg.rt)
        freeze_gc(cfg.rt.gc_freeze)
        log.info(
            "%s on %s:%s at %g Hz, scenario %s",
            cfg.mode,
            cfg.bus.interface,
            cfg.bus.channel,
            cfg.rate_hz,
            scenario.name,
        )
        if cfg.mode == "lockstep":
            n = scenario.n_samples if args.duration is None else round(args.duration * cfg.rate_hz)
            ok = proc.run_lockstep(stop, n)
        else:
            ok = proc.run_realtime(stop, realtime_periods(args, cfg.rate_hz, scenario))
    finally:
        restore_handlers(previous)
        io.close()
        bus.shutdown()
    summary = {**proc.summary(), "rejected_datagrams": io.rejected_datagrams()}
    publish_summary(format_summary, summary, args.summary_json)
    return 0 if ok else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``firmware-sim`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        stream=sys.stderr,
        format="firmware-sim: %(levelname)s: %(message)s",
    )
    return run_console("firmware-sim", lambda: run(args))


if __name__ == "__main__":
    sys.exit(main())
