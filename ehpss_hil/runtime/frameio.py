"""Frame I/O at the edge of a loop: encode + send + log, non-blocking drain, ID collisions.

Each frame is logged exactly once: when sent, or when received. A frame received on one of the
process's own TX IDs (``own_ids``) is never handed to the loop: either it is the echo of one the
process sent (dropped unlogged) or another node sent it — an ID collision, counted per frame name
(:attr:`FrameIO.collisions`, :mod:`.collisions`) and logged. Which it is depends on the bus
(:func:`~ehpss_hil.bus.suppress_own_echoes`): socketcan and ``virtual`` (as opened here) never
hand a process its own frames, and on ``udp_multicast`` a kernel socket filter drops the
datagrams from the process's own sending port (no read, no decoding), so every frame on an own
ID that arrives is foreign; where echoes do come back, a ring of the frames sent
(:class:`~.collisions.SentFrames`) tells them apart. On ``udp_multicast`` the drain reads
without a ``select()`` per frame (:func:`~ehpss_hil.bus.frame_reader`) and frames go out without
python-can's per-frame packing (:func:`~ehpss_hil.bus.frame_writer`). Every other frame is
logged when received, then handed to the loop, which classifies only the IDs it consumes.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from typing import Any, Protocol

import can

from ..bus import (
    datagram_rejects,
    frame_reader,
    frame_writer,
    stamps_receive_time,
    suppress_own_echoes,
)
from ..codec import FrameCodec
from ..codec.ratelimit import RateLimit, position_step_bound_m
from ..config import BusConfig, CanIds, Cia408Config, DbcMap, LogConfig
from ..errors import ConfigError, FrameError, MissingExtraError, OutputError
from ..protocol import make_codec
from .bushealth import BusHealth
from .collisions import IdCollisions, SentFrames

log = logging.getLogger(__name__)


class FrameLogger(Protocol):
    """What a loop needs of ``ehpss_hil.canlog.CandumpLogger`` (any of its formats)."""

    def log(self, msg: can.Message) -> None: ...

    def kick(self) -> None: ...

    def note(self, key: str, value: object) -> None: ...

    def close(self) -> object: ...


def open_can_logger(
    path: str,
    cfg: LogConfig,
    bus: BusConfig,
    sidecar: dict[str, Any] | None = None,
    overwrite: bool = False,
    fmt: str | None = None,
) -> FrameLogger | None:
    """A CAN logger for ``path`` (None when ``path`` is empty) in ``fmt`` (``candump``, ``blf``,
    ``mf4``; None: ``cfg.format``, whose ``auto`` goes by the suffix); ``overwrite``: replace a
    file at ``path`` that is no log of ours (``--overwrite``)."""
    if not path:
        return None
    from ..canlog import CandumpLogger

    iface = bus.channel if bus.interface == "socketcan" else "can0"
    logger: FrameLogger = CandumpLogger(
        path,
        iface=iface,
        max_bytes=cfg.max_bytes,
        backups=cfg.backups,
        queue_lines=cfg.queue_lines,
        sidecar=sidecar,
        overwrite=overwrite,
        fmt=fmt or cfg.format,
    )
    return logger


def process_codec(
    dbc: str,
    ids: CanIds,
    config_path: str,
    protocol: str = "native",
    dbc_map: DbcMap | None = None,
    cia408: Cia408Config | None = None,
    spool_stroke_m: float = 0.0,
    stroke_current_a: float = 0.0,
) -> FrameCodec:
    """The frame codec of a process config (:func:`ehpss_hil.protocol.make_codec`): its DBC
    (empty: the shipped one), ID layout and protocol profile; a bad DBC, map or ID layout is a
    :class:`ConfigError` naming its key (exit 2). ``spool_stroke_m`` (m), ``stroke_current_a``
    (A): the plant's spool stroke and the coil current that reaches it."""
    return make_codec(protocol, dbc, ids, config_path, dbc_map, cia408, spool_stroke_m, stroke_current_a)


def limit_sensor_rate(codec: FrameCodec, speed_max_m_s: float, ts_s: float) -> RateLimit:
    """The rate plausibility check of SENSOR_POS Position (:mod:`~ehpss_hil.codec.ratelimit`)
    for a plant whose piston moves at most ``speed_max_m_s`` (m/s), sampled every ``ts_s`` (s);
    the daemon and ``replay`` classify alike."""
    return codec.limit_rate("SENSOR_POS", "Position", position_step_bound_m(speed_max_m_s, ts_s))


def open_process_logger(
    cli_path: str | None,
    cfg: LogConfig,
    bus_cfg: BusConfig,
    bus: can.BusABC,
    config_path: str,
    sidecar: dict[str, Any],
    overwrite: bool = False,
    fmt: str | None = None,
) -> FrameLogger | None:
    """:func:`open_can_logger` for a process whose bus is open (``--log`` wins over
    ``log.path``, ``--log-format`` (``fmt``) over ``log.format``): a log that cannot be
    written, a name that disagrees with its format, or a file there that is no log of ours
    (unless ``overwrite``) shuts the bus (nothing was sent yet) and is a :class:`ConfigError`
    naming the option or key it came from (exit 2); MF4 without asammdf is a
    :class:`~ehpss_hil.errors.MissingExtraError` (exit 2)."""
    try:
        return open_can_logger(
            cli_path or cfg.path, cfg, bus_cfg, sidecar=sidecar, overwrite=overwrite, fmt=fmt
        )
    except MissingExtraError:
        bus.shutdown()
        raise
    except OutputError as exc:
        bus.shutdown()
        raise ConfigError(config_path, "--log" if cli_path else "log.path", str(exc)) from exc
    except OSError as exc:
        bus.shutdown()
        raise ConfigError(
            config_path, "--log" if cli_path else "log.path", f"cannot write the log: {exc}"
        ) from exc


#: after a failed receive, :meth:`FrameIO.recv` waits this long (at most) before returning
RX_ERROR_PAUSE_S = 0.001


class FrameIO:
    """One process's view of the bus: counts sent frames by name, transmit errors and ID
    collisions (frames on the own TX IDs that this process did not send)."""

    def __init__(
        self,
        bus: can.BusABC,
        codec: FrameCodec,
        own_names: tuple[str, ...],
        logger: FrameLogger | None = None,
    ) -> None:
        self.bus = bus
        self.codec = codec
        self.logger = logger
        self.own_ids = frozenset(codec.can_id(n) for n in own_names)
        #: True when the bus never hands this process its own frames (then every frame received
        #: on an own ID is another node's); else :attr:`_echoes` tells echoes apart
        self.echoes_suppressed = suppress_own_echoes(bus)
        self._echoes = None if self.echoes_suppressed else SentFrames()
        #: foreign frames received on the own TX IDs, per frame name
        self.collisions = IdCollisions({codec.can_id(n): n for n in own_names})
        #: True when a received frame's timestamp is its receive time (wall clock)
        self.receive_timestamps = stamps_receive_time(bus)
        # every DBC frame's datagram template built now, not in the first cycles (udp_multicast)
        shapes = {n: codec.shape(n) for n in codec.names}
        self._read = frame_reader(bus, (m for n, m in shapes.items() if n not in own_names))
        self._write = frame_writer(bus, (shapes[n] for n in own_names))
        self.sent: dict[str, int] = {n: 0 for n in own_names}
        #: frames that could not be encoded (counted in :attr:`tx_errors`, not a bus error)
        self.encode_errors = 0
        self.received = 0
        #: send failures and error frames (the controller loop gives it its watchdog policy)
        self.health = BusHealth()

    @property
    def tx_errors(self) -> int:
        """Frames not sent: encode failures and send failures."""
        return self.encode_errors + self.health.tx_errors

    def send(self, name: str, values: dict[str, Any]) -> can.Message | None:
        """Encode, send and log one frame; returns it, or None when encode/send failed."""
        msg = self._encode(name, values)
        return msg if msg is not None and self._emit(name, msg) else None

    def send_message(self, name: str, msg: can.Message) -> bool:
        """Send, count (under ``name``) and log a frame built by the caller; True when sent."""
        return self._emit(name, msg)

    def send_together(self, *frames: tuple[str, dict[str, Any]]) -> int:
        """Encode every frame first, then send them back to back (in order), so that they leave
        as close together as the bus allows (the emulator's sensor pair: the controller's cycle
        waits for the second); returns how many were sent."""
        msgs = [(name, self._encode(name, values)) for name, values in frames]
        return sum(1 for name, msg in msgs if msg is not None and self._emit(name, msg))

    def _encode(self, name: str, values: dict[str, Any]) -> can.Message | None:
        try:
            return self.codec.encode(name, values, timestamp_s=time.time())
        except FrameError as exc:
            self.encode_errors += 1
            if self.encode_errors == 1 or self.encode_errors % 1000 == 0:
                log.warning("%s not encoded (%d so far): %s", name, self.encode_errors, exc)
            return None

    def _emit(self, name: str, msg: can.Message) -> bool:
        try:
            self._write(msg)
        except (can.CanError, OSError) as exc:
            self.health.tx_failed(name, exc)
            return False
        self.sent[name] = self.sent.get(name, 0) + 1
        if self._echoes is not None:
            self._echoes.add(msg.arbitration_id, msg.data)
        if self.logger is not None:
            self.logger.log(msg)
        return True

    def idle(self) -> None:
        """The loop is done with its cycle and about to sleep: the log writer may run now
        (rather than in the middle of a cycle, holding the GIL the loop needs)."""
        if self.logger is not None:
            self.logger.kick()

    def _accept(self, msg: can.Message | None) -> bool:
        """Count and log a received frame; True when it is for the loop (not on an own ID)."""
        if msg is None:
            return False
        if msg.is_error_frame:  # the bus's word on its own state, not a frame for anyone
            self.health.error_frame(msg)
            self.received += 1
            if self.logger is not None:
                self.logger.log(msg)
            return False
        own = msg.arbitration_id in self.own_ids
        if own and self._echoes is not None and self._echoes.take(msg.arbitration_id, msg.data):
            return False  # the echo of a frame this process sent (logged when sent)
        if own:
            self.collisions.add(msg.arbitration_id)
        self.received += 1
        if self.logger is not None:
            self.logger.log(msg)
        return not own

    def drain(self, limit: int = 1000) -> Iterator[can.Message]:
        """Every frame pending now (non-blocking) but those on own IDs; at most ``limit`` read."""
        read = self._read
        for _ in range(limit):
            try:
                msg = read()
            except (can.CanError, OSError) as exc:  # e.g. ENETDOWN: the interface went down
                self.health.rx_failed(exc)
                return
            if msg is None:
                return
            if self._accept(msg):
                yield msg

    def recv(self, timeout_s: float) -> can.Message | None:
        """Wait up to ``timeout_s`` (s) for one frame not on an own ID."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            try:
                msg = self.bus.recv(max(left, 0.0))
            except (can.CanError, OSError) as exc:
                self.health.rx_failed(exc)
                time.sleep(max(0.0, min(left, RX_ERROR_PAUSE_S)))  # not a busy loop on a dead bus
                return None
            if msg is None:
                return None
            if self._accept(msg):
                return msg
            if left <= 0.0:
                return None

    def rejected_datagrams(self) -> dict[str, Any]:
        """Datagrams skipped as no frame: ``{"total": n, "by_reason": {...}}`` (zero on buses
        that cannot carry such datagrams)."""
        rejects = datagram_rejects(self.bus)
        return rejects.as_dict() if rejects is not None else {"total": 0, "by_reason": {}}

    def close(self) -> None:
        """Flush/close the log (the bus is closed by its owner); the log's sidecar gets the
        count of rejected datagrams."""
        if self.logger is not None:
            self.logger.note("rejected_datagrams", self.rejected_datagrams())
            self.logger.close()
            self.logger = None
