"""The controller daemon (``ehpss-hil controller``): config → bus, codec, controller, loop.

Realtime on a fixed deadline grid (default) or lockstep (one cycle per received sensor pair).
SIGTERM/SIGINT stop the loop at its next cycle; then the daemon sends zero current with
Enable 0, reports STOPPED, flushes the log and returns 0.
"""

from __future__ import annotations

import importlib
import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from .blas import limit_blas_threads
from .bus import open_bus
from .bus.bitrate import BITRATE_UNCHECKED, check_bitrate
from .config import (
    DAEMON_MODES,
    ControllerConfig,
    RtOptions,
    apply_overrides,
    load_controller_config,
)
from .control.base import Controller
from .errors import ConfigError
from .physics.load import load_params
from .physics.params import Params
from .protocol.travel import check_controller_travel
from .runtime.controller_loop import CIA408_OWN_FRAMES, OWN_FRAMES, ControllerLoop, LoopOptions
from .runtime.frameio import FrameIO, limit_sensor_rate, open_process_logger, process_codec
from .runtime.loop_run import loop_summary, run_lockstep, run_realtime
from .runtime.rt import apply_rt_options, freeze_gc
from .runtime.signals import install_stop_handlers, restore_handlers
from .runtime.stats import publish_summary, rejects_text

log = logging.getLogger("ehpss_hil.controller")

CLOCK_NOTE = (
    "wall clock (time.time()) at send for frames sent; the bus's receive timestamp "
    "(kernel SO_TIMESTAMPNS on udp_multicast/socketcan) for frames received"
)
ControllerFactory = Callable[[str, Params, float, ControllerConfig], Controller]


@dataclass(frozen=True)
class DaemonArgs:
    """Command-line overrides of ``controller.yaml`` (None = keep the config's value)."""

    config: Path
    interface: str | None = None
    channel: str | None = None
    mode: str | None = None
    rate_hz: float | None = None
    rt_priority: int | None = None
    cpu: int | None = None
    log: str | None = None
    #: replace a file at ``log`` that is no log of ours (``--overwrite``)
    overwrite_log: bool = False
    #: ``--log-format``: candump, blf, mf4 (None: ``log.format``, by default the suffix's)
    log_format: str | None = None
    duration_s: float | None = None
    lockstep: bool = False
    #: lockstep: end after this long without frames (s; None: ``LoopOptions``' default)
    lockstep_idle_s: float | None = None
    summary_json: Path | None = None
    controller_factory: str | None = None
    sensor_age_us: float | None = None
    #: a factory given in code (``ehpss-hil identify -c``); it wins over ``controller_factory``
    factory: ControllerFactory | None = None


def resolve_config(a: DaemonArgs) -> ControllerConfig:
    """Load the config and apply the overrides, validated (raises ConfigError)."""
    cfg = load_controller_config(a.config)
    src = str(a.config)
    bus = cfg.bus
    bus, rate, rt = apply_overrides(
        src,
        bus,
        cfg.rate_hz,
        cfg.rt,
        interface=a.interface,
        channel=a.channel,
        rate=a.rate_hz,
        rt_priority=a.rt_priority,
        cpu=a.cpu,
    )
    mode = a.mode or cfg.mode
    if mode not in DAEMON_MODES:
        raise ConfigError(src, "mode (--mode)", f"expected one of {', '.join(DAEMON_MODES)}")
    if a.duration_s is not None and a.duration_s <= 0.0:
        raise ConfigError(src, "--duration", "must be > 0 s")
    if a.lockstep_idle_s is not None and not 0.0 < a.lockstep_idle_s < math.inf:
        raise ConfigError(src, "--lockstep-idle", "must be a finite number of seconds > 0")
    return replace(cfg, bus=bus, rate_hz=rate, mode=mode, rt=rt)  # type: ignore[arg-type]


def default_factory(mode: str, params: Params, ts_s: float, cfg: ControllerConfig) -> Controller:
    """The project's control laws (``ehpss_hil.control.controllers.make_controller``)."""
    from .control.registry import make_controller

    return make_controller(mode, params, ts_s, cfg.tuning, reference=cfg.reference)


def load_factory(spec: str | None) -> ControllerFactory:
    """``module:function`` → a controller factory (tests, custom laws); None → the default."""
    if not spec:
        return default_factory
    mod_name, _, func = spec.partition(":")
    try:
        fn: ControllerFactory = getattr(importlib.import_module(mod_name), func)
    except (ImportError, AttributeError) as exc:
        raise ConfigError("", "--controller-factory", f"cannot load {spec!r}: {exc}") from exc
    return fn


def loop_options(cfg: ControllerConfig, sensor_age_us: float | None = None) -> LoopOptions:
    """The loop's rates, fail-safe policy and phase-lock target from the config (+ override)."""
    opts = LoopOptions(
        rate_hz=cfg.rate_hz,
        status_rate_hz=cfg.status_rate_hz,
        heartbeat_rate_hz=cfg.heartbeat_rate_hz,
        watchdog=cfg.watchdog,
        setpoint=cfg.setpoint,
        stats_interval_s=cfg.stats_interval_s,
    )
    key = "--sensor-age-us" if sensor_age_us is not None else "rt.sensor_age_us"
    age_us = sensor_age_us if sensor_age_us is not None else cfg.rt.sensor_age_us
    if not 0.0 <= age_us * 1e-6 < 0.5 / cfg.rate_hz:
        raise ConfigError("", key, f"must be in [0, half a period = {0.5e6 / cfg.rate_hz:g} µs)")
    return replace(opts, sensor_age_target_s=age_us * 1e-6, wake_on_sensor=cfg.rt.wake_on_sensor)


def format_summary(s: dict[str, object]) -> str:
    """The counters printed at exit."""
    st = s["stats"]
    assert isinstance(st, dict)
    lat, cmp_, lcy = st["lateness_s"], st["compute_s"], st["latency_s"]
    return "\n".join(
        [
            f"controller: cycles {s['cycles']}, final state {s['state']} "
            f"(reason {s['failsafe_reason']}), watchdog trips {s['watchdog_trips']}, "
            f"fail-safe cycles {s['failsafe_cycles']}, saturations {s['saturations']}",
            f"  frames sent: {s['frames_sent']} (tx errors {s['tx_errors']})",
            f"  frames received: {s['frames_received']}; by verdict {s['received_by_verdict']}",
            f"  datagrams rejected (not a frame): {rejects_text(s)}",
            f"  ID collisions (foreign frames on own IDs): {s['id_collisions']}; second "
            f"transmitter: {s['second_transmitter']}; SETPOINT {s['setpoints']}",
            f"  overruns {st['overruns']}, lateness p50 {lat['p50'] * 1e6:.1f} µs p99 "
            f"{lat['p99'] * 1e6:.1f} µs, compute p99 {cmp_['p99'] * 1e6:.1f} µs, sensor->command "
            f"latency p50 {lcy['p50'] * 1e6:.1f} µs p99 {lcy['p99'] * 1e6:.1f} µs",
        ]
    )


def run_daemon(a: DaemonArgs) -> int:
    """Configure, run until stopped, shut down fail-safe; returns the exit code (0)."""
    cfg = resolve_config(a)
    params = load_params(cfg.params or None)
    if a.lockstep and cfg.protocol == "cia408":
        raise ConfigError(
            str(a.config), "protocol", "cia408 runs in realtime only (the master's SYNC paces the nodes)"
        )
    plant = params.plant
    codec = process_codec(
        cfg.dbc,
        cfg.ids,
        str(a.config),
        cfg.protocol,
        cfg.dbc_map,
        cfg.nodes,
        plant.spool_stroke_m,
        plant.stroke_current_a,
    )
    check_controller_travel(codec, cfg, str(a.config))
    limit_sensor_rate(codec, params.plant.piston_speed_max_m_s, 1.0 / cfg.rate_hz)
    factory = a.factory or load_factory(a.controller_factory)
    controller = factory(cfg.mode, params, 1.0 / cfg.rate_hz, cfg)
    if not isinstance(controller, Controller):
        raise ConfigError(
            "",
            "--controller-factory",
            f"returned a {type(controller).__name__}, not a Controller",
        )
    note = check_bitrate(cfg.bus, str(a.config))  # a bit rate other than the interface's: exit 2
    # an interface without a bit rate (vcan, udp_multicast, virtual) is not news on every start
    log.log(logging.DEBUG if note.endswith(BITRATE_UNCHECKED) else logging.INFO, note)
    bus = open_bus(cfg.bus)
    try:  # until the loop's own shutdown takes over: the bus (and the log) closed on any error
        logger = open_process_logger(
            a.log,
            cfg.log,
            cfg.bus,
            bus,
            str(a.config),
            sidecar={
                "tool": "ehpss-hil controller",
                "config": asdict(cfg),
                "config_path": str(a.config),
                "dbc": cfg.dbc or None,
                "mode": cfg.mode,
                "rate_hz": cfg.rate_hz,
                "clock": CLOCK_NOTE,
                "bus": f"{cfg.bus.interface}:{cfg.bus.channel}",
                "lockstep": a.lockstep,
            },
            overwrite=a.overwrite_log,
            fmt=a.log_format,
        )
    except BaseException:
        bus.shutdown()
        raise
    io = FrameIO(bus, codec, _own_frames(cfg), logger)
    session = master = None
    try:
        if cfg.protocol == "cia408":
            session, master = _cia408_master(bus, codec, cfg)
        opts = loop_options(cfg, a.sensor_age_us)
        if a.lockstep_idle_s is not None:
            opts = replace(opts, lockstep_idle_s=a.lockstep_idle_s)
        loop = ControllerLoop(controller, io, cfg.reference, opts, master)
    except BaseException:
        io.close()
        bus.shutdown()
        raise
    stop, previous = install_stop_handlers()
    n = None if a.duration_s is None else round(a.duration_s * cfg.rate_hz)
    try:
        limit_blas_threads(1)  # idle OpenBLAS workers spin and steal the loop's CPU
        _prepare_rt(cfg.rt)
        loop.start()
        if session is not None:
            session.start(codec)  # type: ignore[arg-type]
        log.info(
            "mode %s on %s:%s at %g Hz%s",
            cfg.mode,
            cfg.bus.interface,
            cfg.bus.channel,
            cfg.rate_hz,
            " (lockstep)" if a.lockstep else "",
        )
        if a.lockstep:
            run_lockstep(loop, stop, n)
        else:
            run_realtime(loop, stop, n)
    finally:
        try:
            loop.shutdown()
            if session is not None:
                session.stop()
        finally:
            restore_handlers(previous)
            io.close()
            bus.shutdown()
    summary = {**loop_summary(loop), "rejected_datagrams": io.rejected_datagrams()}
    publish_summary(format_summary, summary, a.summary_json)
    return 0


def _own_frames(cfg: ControllerConfig) -> tuple[str, ...]:
    """The frames the controller sends: the CANopen master's besides (SYNC only when it is the
    producer; a SYNC from another node is then no collision)."""
    if cfg.protocol != "cia408":
        return OWN_FRAMES
    return (*OWN_FRAMES, *(f for f in CIA408_OWN_FRAMES if f != "SYNC" or cfg.nodes.sync == "produce"))


def _cia408_master(bus: Any, codec: Any, cfg: ControllerConfig) -> tuple[Any, Any]:
    """The CANopen master's start-up session and its part of each cycle (``protocol: cia408``)."""
    from .protocol.cia408.master import CyclicMaster, MasterSession

    return MasterSession(bus, cfg.nodes), CyclicMaster(codec, cfg.nodes, cfg.rate_hz)


def _prepare_rt(rt: RtOptions) -> None:
    apply_rt_options(rt)
    freeze_gc(rt.gc_freeze)
