"""Process configuration (``configs/controller.yaml``, ``configs/emulator.yaml``) as frozen
dataclasses, validated with precise errors (file, key path, expectation)."""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from .control.tuning import ControlTuning
from .errors import ConfigError
from .limits import MAX_RATE_HZ, MIN_RATE_HZ
from .profile_config import (
    PROTOCOLS,
    Cia408Config,
    DbcMap,
    E2EFrameMap,
    E2EMap,
    Protocol,
    SignalMap,
    check_protocol,
)
from .scenario import Reference
from .schema import build, load_yaml, rng

Mode = Literal["nrc", "smac", "mmac-paper", "mmac", "oracle"]
DAEMON_MODES = ("nrc", "smac", "mmac-paper", "mmac")

#: the embedded default bus: an administratively scoped IPv4 group, TTL 0 (never leaves the host)
DEFAULT_MULTICAST_GROUP = "239.74.163.2"

#: the profile sections (profile_config.py) are part of this module's interface
__all__ = ["PROTOCOLS", "Cia408Config", "DbcMap", "E2EFrameMap", "E2EMap", "Protocol", "SignalMap"]


@dataclass(frozen=True)
class BusConfig:
    """python-can bus selection, like python-can's own config keys.

    ``udp_multicast`` (the embedded default) is confined to this host: the group must be IPv4 in
    239.0.0.0/8 (or IPv6 link/interface-local ff01::/16, ff02::/16) and ``hop_limit`` must be 0.
    """

    interface: Literal["udp_multicast", "socketcan", "virtual"] = "udp_multicast"
    channel: str = DEFAULT_MULTICAST_GROUP
    bitrate: int = field(default=1_000_000, metadata=rng(10_000, 1_000_000))
    port: int = field(default=43113, metadata=rng(1024, 65535))
    hop_limit: int = field(default=0, metadata=rng(0, 0))
    receive_buffer_bytes: int = field(default=4 * 1024 * 1024, metadata=rng(65536, 256 * 2**20))

    def __post_init__(self) -> None:
        if self.interface == "udp_multicast":
            try:
                addr = ipaddress.ip_address(self.channel)
            except ValueError as exc:
                raise ConfigError("", "channel", f"not an IP multicast group: {self.channel!r}") from exc
            ok = (addr.version == 4 and addr in ipaddress.ip_network("239.0.0.0/8")) or (
                addr.version == 6 and any(addr in ipaddress.ip_network(n) for n in ("ff01::/16", "ff02::/16"))
            )
            if not ok:
                raise ConfigError(
                    "",
                    "channel",
                    "udp_multicast group must be in 239.0.0.0/8 "
                    f"(or ff01::/16, ff02::/16) so frames stay on this host; "
                    f"got {self.channel}",
                )
        elif not self.channel:
            raise ConfigError("", "channel", "must name the interface (e.g. vcan0, can0)")


@dataclass(frozen=True)
class CanIds:
    """Frame ID layout: the DBC's application frames shifted to ``id_base``; heartbeats at
    0x700 + node id. ``max_delta_counter``: E2E counter jumps accepted as OK_SOME_LOST."""

    id_base: int = field(default=0x100, metadata=rng(0, 0x790))
    controller_node: int = field(default=1, metadata=rng(1, 127))
    emulator_node: int = field(default=2, metadata=rng(1, 127))
    max_delta_counter: int = field(default=3, metadata=rng(1, 14))

    def __post_init__(self) -> None:
        if self.controller_node == self.emulator_node:
            raise ConfigError("", "emulator_node", "must differ from controller_node")


@dataclass(frozen=True)
class LogConfig:
    """The process's CAN log: empty path = no log. ``format``: ``candump`` (``-L``), ``blf`` or
    ``mf4`` (``ehpss_hil.canlog.formats``), ``auto`` = by the path's suffix (``.blf``, ``.mf4``,
    else candump). Rotation by size (candump only); writer queue bound (frames)."""

    path: str = ""
    format: Literal["auto", "candump", "blf", "mf4"] = "auto"
    max_bytes: int = field(default=256 * 2**20, metadata=rng(4096, 2**40))
    backups: int = field(default=5, metadata=rng(0, 1000))
    queue_lines: int = field(default=200_000, metadata=rng(1000, 10_000_000))


@dataclass(frozen=True)
class RtOptions:
    """Real-time options; each warns clearly when not permitted. ``cpu`` −1 = no affinity."""

    priority: int = field(default=0, metadata=rng(0, 99))
    cpu: int = field(default=-1, metadata=rng(-1, 1023))
    lock_memory: bool = False
    gc_freeze: bool = True
    #: phase lock: the controller's deadline falls this long after the SENSOR_POS frame
    #: arrives (µs; 0 = a free grid; must be below half a period). See docs/runtime.md.
    sensor_age_us: float = field(default=0.0, metadata=rng(0.0, 1e6))
    #: start each cycle as soon as its SENSOR_POS + SENSOR_AUX have arrived (the deadline is
    #: then the latest start): sensor→command latency ≈ compute time. See docs/runtime.md.
    wake_on_sensor: bool = False


@dataclass(frozen=True)
class Watchdog:
    """Fail-safe: no valid sensor frame for ``timeout_cycles`` → ``failsafe`` action, state FAULT.

    Leaves FAULT after ``recovery_cycles`` fresh cycles only when ``auto_recover`` is true.
    Loop starvation (LOOP_OVERRUN): at least ``starvation_late_fraction`` of the last
    ``starvation_window_cycles`` grid periods late or skipped (docs/runtime.md).
    ``on_collision``: a second transmitter (a foreign VALVE_CMD, the emulator's CommandConflict,
    a second SENSOR_POS stream) is a fault (ID_COLLISION) or only counted and warned about.
    """

    timeout_cycles: int = field(default=3, metadata=rng(1, 10000))
    recovery_cycles: int = field(default=50, metadata=rng(1, 1_000_000))
    auto_recover: bool = False
    failsafe: Literal["zero", "hold"] = "zero"
    max_e2e_errors: int = field(default=10, metadata=rng(1, 1_000_000))
    starvation_window_cycles: int = field(default=200, metadata=rng(10, 1_000_000))
    starvation_late_fraction: float = field(default=0.25, metadata=rng(0.0, 1.0, lo_open=True))
    on_collision: Literal["fault", "warn"] = "fault"


@dataclass(frozen=True)
class SetpointPolicy:
    """SETPOINT frames (a host's x_d override, m). The frame names no sender, so a source is
    allowed by ``enabled`` alone; an override beyond ``max_abs_m`` or more than ``max_step_m``
    from the x_d in force is rejected (counted). Disabled: every SETPOINT is rejected."""

    enabled: bool = False
    max_abs_m: float = field(default=0.05, metadata=rng(0.0, 0.5))
    max_step_m: float = field(default=0.005, metadata=rng(0.0, 1.0))


@dataclass(frozen=True)
class ControllerConfig:
    """``configs/controller.yaml``."""

    bus: BusConfig = field(default_factory=BusConfig)
    ids: CanIds = field(default_factory=CanIds)
    mode: Mode = "mmac"
    rate_hz: float = field(default=1000.0, metadata=rng(MIN_RATE_HZ, MAX_RATE_HZ))
    reference: Reference = field(default_factory=Reference)
    watchdog: Watchdog = field(default_factory=Watchdog)
    setpoint: SetpointPolicy = field(default_factory=SetpointPolicy)
    status_rate_hz: float = field(default=50.0, metadata=rng(1.0, 1000.0))
    heartbeat_rate_hz: float = field(default=10.0, metadata=rng(0.1, 100.0))
    stats_interval_s: float = field(default=10.0, metadata=rng(0.0, 86400.0))
    rt: RtOptions = field(default_factory=RtOptions)
    log: LogConfig = field(default_factory=LogConfig)
    tuning: ControlTuning = field(default_factory=ControlTuning)
    params: str = ""
    dbc: str = ""
    protocol: Protocol = "native"
    dbc_map: DbcMap | None = None

    cia408: Cia408Config | None = None

    def __post_init__(self) -> None:
        check_protocol(self.protocol, self.dbc_map)
        if self.protocol == "cia408":
            self._check_cia408()
        elif self.cia408 is not None:
            raise ConfigError("", "cia408", f"only read with protocol: cia408 (protocol is {self.protocol})")
        if self.mode not in DAEMON_MODES:
            raise ConfigError(
                "",
                "mode",
                "oracle is for benchmarks only, not for the daemon "
                f"(expected one of {', '.join(DAEMON_MODES)})",
            )
        if not self.rt.sensor_age_us * 1e-6 < 0.5 / self.rate_hz:
            raise ConfigError(
                "",
                "rt.sensor_age_us",
                f"must be below half a period ({0.5e6 / self.rate_hz:g} µs at rate_hz {self.rate_hz:g})",
            )
        for key in ("k_loe_limits", "k_dft_limits", "baseline_limits"):
            lo, hi = getattr(self.tuning, key)
            if not lo < hi:
                raise ConfigError(
                    "", f"tuning.{key}", f"expected [low, high] with low < high, got [{lo:g}, {hi:g}]"
                )

    def _check_cia408(self) -> None:
        """The master's own constraints: its heartbeat is the controller's (0x700 + node), and a
        CiA 408 valve in spool-position mode reports no load pressure for mmac's flow-gain test."""
        if self.nodes.master_node != self.ids.controller_node:
            raise ConfigError(
                "",
                "cia408.master_node",
                f"must equal ids.controller_node ({self.ids.controller_node}): the valve consumes the "
                "controller's heartbeat",
            )
        n = self.nodes
        if n.heartbeat_time_ms and n.node_heartbeat_timeout_ms <= n.heartbeat_time_ms:
            raise ConfigError(
                "",
                "cia408.node_heartbeat_timeout_ms",
                f"must exceed cia408.heartbeat_time_ms ({n.heartbeat_time_ms} ms), the nodes' period",
            )
        if self.mode == "mmac" and self.tuning.flow_gain_test:
            raise ConfigError(
                "",
                "tuning.flow_gain_test",
                "must be false with protocol cia408 (the valve reports no load pressure)",
            )

    @property
    def nodes(self) -> Cia408Config:
        """The CANopen node settings (``cia408:``, or their defaults)."""
        return self.cia408 if self.cia408 is not None else Cia408Config()


@dataclass(frozen=True)
class EmulatorConfig:
    """``configs/emulator.yaml``."""

    bus: BusConfig = field(default_factory=BusConfig)
    ids: CanIds = field(default_factory=CanIds)
    rate_hz: float = field(default=1000.0, metadata=rng(MIN_RATE_HZ, MAX_RATE_HZ))
    mode: Literal["realtime", "lockstep"] = "realtime"
    command_timeout_s: float = field(default=0.010, metadata=rng(0.0, 10.0, lo_open=True))
    truth: bool = False
    fault_inject: bool = False
    scenario: str = ""
    heartbeat_rate_hz: float = field(default=10.0, metadata=rng(0.1, 100.0))
    rt: RtOptions = field(default_factory=RtOptions)
    log: LogConfig = field(default_factory=LogConfig)
    params: str = ""
    dbc: str = ""
    protocol: Protocol = "native"
    dbc_map: DbcMap | None = None
    cia408: Cia408Config | None = None

    def __post_init__(self) -> None:
        check_protocol(self.protocol, self.dbc_map)
        if self.protocol != "cia408":
            if self.cia408 is not None:
                raise ConfigError(
                    "", "cia408", f"only read with protocol: cia408 (protocol is {self.protocol})"
                )
            return
        if self.mode == "lockstep":
            raise ConfigError(
                "", "mode", "lockstep is not available with protocol cia408 (the nodes run in realtime)"
            )
        if self.fault_inject:
            raise ConfigError(
                "", "fault_inject", "FAULT_INJECT is not read with protocol cia408 (use a device_fault event)"
            )

    @property
    def nodes(self) -> Cia408Config:
        """The CANopen node settings (``cia408:``, or their defaults)."""
        return self.cia408 if self.cia408 is not None else Cia408Config()


def apply_overrides(
    src: str,
    bus: BusConfig,
    rate_hz: float,
    rt: RtOptions,
    *,
    interface: str | None = None,
    channel: str | None = None,
    rate: float | None = None,
    rt_priority: int | None = None,
    cpu: int | None = None,
) -> tuple[BusConfig, float, RtOptions]:
    """Command-line overrides of a process config's bus, rate and RT options, validated like
    the YAML (errors name the key and the option)."""
    from dataclasses import replace

    if interface or channel:
        try:
            bus = replace(
                bus,
                interface=interface or bus.interface,  # type: ignore[arg-type]
                channel=channel or bus.channel,
            )
        except ConfigError as exc:
            raise ConfigError(src, f"bus.{exc.key_path} (command line)", exc.reason) from exc
    rate_hz = rate_hz if rate is None else rate
    if not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
        raise ConfigError(
            src, "rate_hz (--rate)", f"must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate_hz:g}"
        )
    if rt_priority is not None:
        if not 0 <= rt_priority <= 99:
            raise ConfigError(src, "rt.priority (--rt-priority)", "must be in [0, 99]")
        rt = replace(rt, priority=rt_priority)
    if cpu is not None:
        rt = replace(rt, cpu=cpu)
    return bus, rate_hz, rt


def _existing(src: Path, key: str, value: str) -> str:
    """``value`` when empty (the default file) or an existing file, else a ConfigError for
    ``key`` (so a wrong path is a config error naming its key, before any bus is opened)."""
    if value and not Path(value).is_file():
        what = "not a regular file" if Path(value).exists() else "no such file"
        raise ConfigError(str(src), key, f"{what}: {value}")
    return value


def _resolve(base: Path, value: str) -> str:
    if not value:
        return value
    p = Path(value)
    return str(p if p.is_absolute() else (base / p).resolve())


def _resolve_map(src: Path, base: Path, m: DbcMap | None) -> DbcMap | None:
    """``dbc_map`` with its DBC path resolved against the config's directory and checked."""
    if m is None:
        return None
    from dataclasses import replace

    return replace(m, dbc=_existing(src, "dbc_map.dbc", _resolve(base, m.dbc)))


def load_controller_config(path: str | Path, data: object = None) -> ControllerConfig:
    """Load ``controller.yaml`` (``data``: its parsed content, when the caller read it already);
    relative ``params``/``dbc``/``reference.path`` paths resolve against its directory
    (``log.path`` stays relative to the working directory, like ``--log``); a file reference is
    read now."""
    p = Path(path)
    cfg = build(ControllerConfig, load_yaml(p) if data is None else data, str(p))
    base = p.resolve().parent
    from dataclasses import replace

    return replace(
        cfg,
        params=_existing(p, "params", _resolve(base, cfg.params)),
        dbc=_existing(p, "dbc", _resolve(base, cfg.dbc)),
        dbc_map=_resolve_map(p, base, cfg.dbc_map),
        reference=cfg.reference.loaded(base, str(p)),
        cia408=_resolve_eds(p, base, cfg.cia408),
    )


def load_emulator_config(path: str | Path, data: object = None) -> EmulatorConfig:
    """Load ``emulator.yaml`` (``data``: its parsed content, when the caller read it already);
    relative paths resolve against its directory."""
    p = Path(path)
    cfg = build(EmulatorConfig, load_yaml(p) if data is None else data, str(p))
    base = p.resolve().parent
    from dataclasses import replace

    return replace(
        cfg,
        params=_existing(p, "params", _resolve(base, cfg.params)),
        dbc=_existing(p, "dbc", _resolve(base, cfg.dbc)),
        dbc_map=_resolve_map(p, base, cfg.dbc_map),
        scenario=_existing(p, "scenario", _resolve(base, cfg.scenario)),
        cia408=_resolve_eds(p, base, cfg.cia408),
    )


def _resolve_eds(src: Path, base: Path, c: Cia408Config | None) -> Cia408Config | None:
    """``cia408`` with its EDS paths resolved against the config's directory and checked."""
    if c is None:
        return None
    from dataclasses import replace

    return replace(
        c,
        valve_eds=_existing(src, "cia408.valve_eds", _resolve(base, c.valve_eds)),
        encoder_eds=_existing(src, "cia408.encoder_eds", _resolve(base, c.encoder_eds)),
    )
