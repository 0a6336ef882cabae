"""The protocol-profile sections of ``controller.yaml`` and ``emulator.yaml`` (docs/hardware.md):
``protocol`` and, for ``dbc-map``, the vendor DBC with its signal map; for ``cia408``, the CANopen
nodes. Frozen dataclasses, validated like the rest of the config (``ehpss_hil.config``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from .errors import ConfigError
from .schema import rng

#: the protocol profiles a process may speak to the valve electronics (docs/hardware.md)
PROTOCOLS = ("native", "dbc-map", "cia408")
Protocol = Literal["native", "dbc-map", "cia408"]


@dataclass(frozen=True)
class SignalMap:
    """The controller's logical signals, each as ``MESSAGE.Signal`` of the mapped DBC. Units come
    from the DBC's unit strings (docs/hardware.md lists the ones understood)."""

    position: str  #: piston position sensor (length)
    spool: str  #: spool position, LVDT (length)
    load_pressure: str  #: load pressure P_L (pressure)
    coil_current: str  #: coil current the amplifier applied, its echo (current)
    current_setpoint: str  #: coil current command (current)
    enable: str = ""  #: amplifier enable (0/1); empty: the vendor frame has none


@dataclass(frozen=True)
class E2EFrameMap:
    """E2E fields of one logical frame: ``MESSAGE.Signal`` of its counter and CRC; DataIDs (p02:
    16, one per counter value; p05: 1)."""

    counter: str = ""
    crc: str = ""
    data_ids: tuple[int, ...] = field(default=(), metadata=rng(0, 0xFFFF, length=(0, 16)))


@dataclass(frozen=True)
class E2EMap:
    """End-to-end protection of the mapped frames: ``none``, ``counter`` (a sequence counter
    only), ``p02``/``p05`` (AUTOSAR profile 2/5 CRC through ``cantools.autosar.end_to_end``)."""

    profile: Literal["none", "counter", "p02", "p05"] = "none"
    sensor_pos: E2EFrameMap = field(default_factory=E2EFrameMap)
    sensor_aux: E2EFrameMap = field(default_factory=E2EFrameMap)
    valve_cmd: E2EFrameMap = field(default_factory=E2EFrameMap)


@dataclass(frozen=True)
class DbcMap:
    """``protocol: dbc-map``: a vendor DBC (``dbc``, relative to the config file) and the map of
    the logical signals onto its messages (ehpss_hil/protocol/, docs/hardware.md)."""

    dbc: str
    signals: SignalMap
    e2e: E2EMap = field(default_factory=E2EMap)


@dataclass(frozen=True)
class NodeIdentityConfig:
    """A CANopen node's identity (0x1018.1–3) as the config expects it; a key left out is not
    checked. The master refuses a node that says otherwise (exit 3, naming the node and the
    entry); the emulator impersonates a node with these values."""

    vendor_id: int | None = field(default=None, metadata=rng(0, 0xFFFFFFFF))
    product_code: int | None = field(default=None, metadata=rng(0, 0xFFFFFFFF))
    revision: int | None = field(default=None, metadata=rng(0, 0xFFFFFFFF))


@dataclass(frozen=True)
class Cia408Config:
    """``protocol: cia408``: a CiA 408 valve and a CiA 406 linear encoder — the nodes firmware-sim
    impersonates, and the nodes the controller masters (docs/hardware.md). Node ids 1…127; times
    in ms (0 = off); ``full_scale_current_a``: the coil current of a +100 % set-point (16384), so
    its LSB is full_scale/16384 and must meet the controller's current resolution (the default
    1 mA: the plant's spool reaches its ±10 mm stroke at ≈ 0.61 mA). The emulator takes
    ``heartbeat_time_ms`` (0x1017) and the timeouts 0x1016.1 (the master's heartbeat) and
    0x1400.5 (the set-point RPDO) as power-on values; the master writes the same three by SDO at
    start-up and takes a node whose heartbeat is ``node_heartbeat_timeout_ms`` late as lost;
    ``sync``: the master sends SYNC after each command (``produce``) or another node does
    (``follow``: then ``rt.wake_on_sensor`` starts each cycle on the TPDOs the SYNC brings).
    ``position_source``: the piston position from the encoder's position value (``encoder``)
    or from an INTEGER32 object of the valve (``valve``: ``valve_position_object``/``_sub`` in
    steps of ``valve_position_step_nm``, mapped into the valve's TPDO 2; no encoder node).
    EDS paths: empty = the shipped files (``eds/``). The resolution and the EDS files are
    checked by ``ehpss_hil.protocol.cia408.check``. ``valve_identity``/``encoder_identity``:
    the 0x1018 vendor, product and revision the nodes must have (:class:`NodeIdentityConfig`)."""

    valve_node: int = field(default=32, metadata=rng(1, 127))
    encoder_node: int = field(default=33, metadata=rng(1, 127))
    master_node: int = field(default=1, metadata=rng(1, 127))
    full_scale_current_a: float = field(default=0.001, metadata=rng(0.0, 10.0, lo_open=True))
    heartbeat_time_ms: int = field(default=100, metadata=rng(0, 65535))
    master_heartbeat_timeout_ms: int = field(default=0, metadata=rng(0, 65535))
    setpoint_timeout_ms: int = field(default=0, metadata=rng(0, 65535))
    node_heartbeat_timeout_ms: int = field(default=300, metadata=rng(1, 65535))
    sync: Literal["produce", "follow"] = "produce"
    position_source: Literal["encoder", "valve"] = "encoder"
    valve_position_object: int = field(default=0x2100, metadata=rng(0x2000, 0x9FFF))
    valve_position_sub: int = field(default=0, metadata=rng(0, 254))
    valve_position_step_nm: int = field(default=100, metadata=rng(1, 1_000_000))
    valve_eds: str = ""
    encoder_eds: str = ""
    valve_identity: NodeIdentityConfig = field(default_factory=NodeIdentityConfig)
    encoder_identity: NodeIdentityConfig = field(default_factory=NodeIdentityConfig)

    def __post_init__(self) -> None:
        if self.encoder_node == self.valve_node:
            raise ConfigError("", "encoder_node", f"must differ from valve_node ({self.valve_node})")
        if self.master_node in (self.valve_node, self.encoder_node):
            raise ConfigError("", "master_node", "must differ from valve_node and encoder_node")


def check_protocol(protocol: str, dbc_map: DbcMap | None) -> None:
    """``dbc_map`` is given exactly when ``protocol`` is ``dbc-map``."""
    if protocol == "dbc-map" and dbc_map is None:
        raise ConfigError(
            "", "dbc_map", "required with protocol: dbc-map (the vendor DBC and its signal map)"
        )
    if protocol != "dbc-map" and dbc_map is not None:
        raise ConfigError("", "dbc_map", f"only read with protocol: dbc-map (protocol is {protocol})")
