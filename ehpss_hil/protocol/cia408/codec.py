"""``protocol: cia408`` as a :class:`~ehpss_hil.codec.FrameCodec`: the controller's logical frames
on the PDOs of a CiA 408 valve and a CiA 406 encoder, everything else native.

* SENSOR_AUX is the valve's TPDO 1 (status word, spool actual value). Classified, it gives the
  native SENSOR_AUX signals: ``CoilCurrent``, the current the valve applied over the last
  sample, and ``LoadPressure`` 0 — CiA 408's spool-position mode reports neither, so the echo is
  the master's own set-point of two cycles before (one sample of transport delay: the one the
  valve held over the sample this TPDO carries) when the status word shows ACTIVE, else 0 A; the
  load pressure is absent (``mmac`` runs without its flow-gain test, ``ehpss_hil.config``). It
  also gives ``Spool`` and ``StatusWord``.
* SENSOR_POS is the encoder's TPDO 1 (position value). Both TPDOs answer one SYNC, the valve's
  first (the nodes answer in node order): classified, it gives ``Position`` and the ``Spool`` of
  the newest valve TPDO. A PDO has no sequence counter; SENSOR_POS's counter is the loop cycle
  (mod 16) of the newest SYNC before the TPDO (``encode("SYNC", {"Cycle": n})``, or
  :meth:`Cia408Codec.sync_seen` for another producer's): the node measures when it answers. So
  periods the loop slept through (no SYNC sent) count as sensor samples, as the native E2E
  counter counts the emulator's periods, and the controller's sample clock bridges them. A
  second TPDO under the same newest SYNC (a node that fell behind answers the SYNCs it missed
  all at once, with one sample) is classified OK without values: no new sample.
* SYNC (0x080, no data) is the master's, sent by the loop after each command.
* NMT (0x000: command, node) is the master's alone; the loop sends one when it shuts a valve
  out (``encode("NMT", {"Command": 2, "Node": n})``), so another node's NMT frame is a frame on
  an own ID (a second transmitter).
* A TPDO whose length is not its mapping's is BAD_DLC and counted in
  :attr:`Cia408Codec.bad_length_pdos` (the master's PDO_ERROR).
* VALVE_CMD is the valve's RPDO 1: the control word (:attr:`Cia408Codec.control_word`, set each
  cycle by the master's :class:`~.drive.DeviceDrive`) and ``CurrentSetpoint`` as the ±16384
  set-point (0 without ``Enable`` or when the control word asks for less than ACTIVE).

The emulator's side of a lockstep run encodes SENSOR_POS/SENSOR_AUX and classifies VALVE_CMD with
the same codec (:mod:`.lockstep`).
"""

from __future__ import annotations

import math
from collections import deque
from pathlib import Path
from typing import Any

import can

from ...codec import Decoded, FrameCodec, Verdict
from ...codec.ratelimit import RateLimit
from ...config import CanIds, Cia408Config
from ...errors import ConfigError, FrameError, FrameIdError
from . import cobid
from .cyclic import (
    ENCODER_TPDO,
    NMT_FRAME,
    VALVE_RPDO,
    VALVE_TPDO,
    Scaling,
    frame,
    step_of_nm,
    sync_frame,
    unpack_encoder_tpdo,
    unpack_valve_rpdo,
    unpack_valve_tpdo,
    valve_rpdo,
    valve_tpdo,
)
from .objects import BIT_D, BIT_H, BIT_M, BIT_R, STATE_BITS, STATUS_OF, DeviceState

_ACTIVE_REQUEST = BIT_D | BIT_H | BIT_M
_ACTIVE_STATUS = STATUS_OF[DeviceState.ACTIVE]
#: commands back to the one the valve applied over the sample a TPDO carries (one sample of
#: transport delay: the command sent two cycles before the one being computed)
ECHO_DELAY_COMMANDS = 2
#: the logical frames the PDOs carry
MAPPED = ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD")


class Cia408Codec(FrameCodec):
    """The native codec with SENSOR_POS, SENSOR_AUX and VALVE_CMD on the nodes' PDOs."""

    def __init__(
        self,
        valve_node: int,
        encoder_node: int,
        scaling: Scaling,
        dbc_path: str | Path | None = None,
        id_base: int = 0x100,
        node_ids: dict[str, int] | None = None,
        max_delta_counter: int = 3,
        position_from_valve: bool = False,
    ) -> None:
        super().__init__(dbc_path, id_base, node_ids, max_delta_counter)
        self.valve_node = valve_node
        self.encoder_node = encoder_node
        self.scaling = scaling
        self._ids = {
            "SENSOR_POS": (cobid.TPDO2 + valve_node) if position_from_valve else (cobid.TPDO1 + encoder_node),
            "SENSOR_AUX": cobid.TPDO1 + valve_node,
            "VALVE_CMD": cobid.RPDO1 + valve_node,
            "SYNC": cobid.SYNC,
            "NMT": cobid.NMT,
        }
        self._lengths = {
            "SENSOR_POS": ENCODER_TPDO.size,
            "SENSOR_AUX": VALVE_TPDO.size,
            "VALVE_CMD": VALVE_RPDO.size,
            "SYNC": 0,
            "NMT": NMT_FRAME.size,
        }
        self._names = {i: n for n, i in self._ids.items()}
        for name in MAPPED:  # the native IDs of the replaced frames are no longer read
            self._by_id.pop(super().can_id(name), None)
        self._bounds = {n: super(Cia408Codec, self).signal_bounds(n) for n in MAPPED}
        #: the control word the next VALVE_CMD carries (the master's device drive sets it)
        self.control_word = BIT_D
        #: the newest status word of the valve (0: none yet) and the valve TPDOs that carried one
        self.status_word = 0
        self.valve_tpdos = 0
        #: TPDOs received with a length other than their mapping's: (name, length) of the last
        self.bad_length_pdos = 0
        self.last_bad_length: tuple[str, int] = ("", 0)
        self._spool_m = 0.0
        self._applied: deque[float] = deque([0.0] * ECHO_DELAY_COMMANDS, maxlen=ECHO_DELAY_COMMANDS)
        #: the cycles (mod 16) of the SYNCs not answered yet, oldest first
        self._sync: int | None = None  # the cycle (mod 16) of the newest SYNC
        self._pos_sync: int | None = None  # … the last encoder TPDO came under
        self._pos_counter = 0x0F

    # ---- lookup -------------------------------------------------------------------------------
    def native_ids(self) -> list[tuple[str, int]]:
        """(name, ID) of every frame this codec still handles natively."""
        return [(n, super(Cia408Codec, self).can_id(n)) for n in self.names if n not in self._ids]

    @property
    def names(self) -> list[str]:
        """The native DBC's frame names, ``SYNC`` (the master's, sent each cycle) and ``NMT``."""
        return [*super().names, "SYNC", "NMT"]

    def can_id(self, name: str) -> int:
        i = self._ids.get(name)
        return i if i is not None else super().can_id(name)

    def name_of(self, can_id: int) -> str | None:
        return self._names.get(can_id) or super().name_of(can_id)

    def shape(self, name: str) -> can.Message:
        i = self._ids.get(name)
        return super().shape(name) if i is None else frame(i, bytes(self._lengths[name]))

    def data_ids(self, name: str) -> tuple[int, ...] | None:
        return None if name in self._ids else super().data_ids(name)

    def signal_bounds(self, name: str) -> dict[str, tuple[float | None, float | None]]:
        if name in ("SYNC", "NMT"):
            return {}
        return self._bounds[name] if name in self._bounds else super().signal_bounds(name)

    def limit_rate(self, name: str, signal: str, step_m: float) -> RateLimit:
        if name != "SENSOR_POS" or signal != "Position":
            return super().limit_rate(name, signal, step_m)
        limit = RateLimit(step_m)
        self._rate[self._ids[name]] = (signal, limit)
        return limit

    def quantize(self, name: str, values: dict[str, float]) -> dict[str, float]:
        if name in self._ids:
            raise FrameError(f"{name}: quantize is native only; use encode + classify under cia408")
        return super().quantize(name, values)

    def skip(self, name: str) -> None:
        if name not in self._ids:
            super().skip(name)

    # ---- transmit -----------------------------------------------------------------------------
    def _finite(self, name: str, values: dict[str, Any], key: str) -> float:
        x = float(values.get(key, 0.0))
        if not math.isfinite(x):
            raise FrameError(f"{name}: {key} is not finite ({x})")
        return x

    def encode(
        self, name: str, values: dict[str, Any], timestamp_s: float = 0.0, counter: int | None = None
    ) -> can.Message:
        if name not in self._ids:
            return super().encode(name, values, timestamp_s, counter)
        if name == "SYNC":
            self.sync_seen(int(values.get("Cycle", self._next_sync())))
            return sync_frame(timestamp_s)
        if name == "NMT":
            command, node = int(values.get("Command", 0)), int(values.get("Node", 0))
            return frame(cobid.NMT, NMT_FRAME.pack(command & 0xFF, node & 0x7F), timestamp_s)
        sc = self.scaling
        if name == "VALVE_CMD":
            current = self._finite(name, values, "CurrentSetpoint")
            on = bool(values.get("Enable", 0)) and self.control_word & STATE_BITS == _ACTIVE_REQUEST
            raw = sc.setpoint_raw(current) if on else 0
            self._applied.append(sc.current_a(raw))
            return valve_rpdo(self.valve_node, self.control_word, raw, timestamp_s)
        if name == "SENSOR_AUX":
            spool = sc.spool_raw(self._finite(name, values, "Spool"))
            status = int(values.get("StatusWord", _ACTIVE_STATUS))
            return valve_tpdo(self.valve_node, status, spool, timestamp_s)
        raw = sc.position_raw(self._finite(name, values, "Position"))
        return frame(self._ids[name], ENCODER_TPDO.pack(raw), timestamp_s)

    def sync_seen(self, cycle: int) -> None:
        """A SYNC went out (or came from another producer) in loop cycle ``cycle``: the TPDOs
        answering it carry that sample."""
        self._sync = cycle & 0x0F

    def _next_sync(self) -> int:
        return ((self._sync if self._sync is not None else self._pos_counter) + 1) & 0x0F

    # ---- receive ------------------------------------------------------------------------------
    def classify(self, frame: can.Message) -> Decoded:
        name = self._names.get(frame.arbitration_id)
        if (
            name is None
            or frame.is_extended_id
            or frame.is_remote_frame
            or frame.is_error_frame
            or frame.is_fd
        ):
            return super().classify(frame)
        d = self._classify_pdo(name, bytes(frame.data), frame.timestamp)
        self.counts[d.verdict] += 1
        per = self.counts_by_name.get(name)
        if per is None:
            per = self.counts_by_name[name] = {v: 0 for v in Verdict}
        per[d.verdict] += 1
        return d

    def _in_range(self, name: str, signal: str, x: float) -> bool:
        lo, hi = self._bounds[name].get(signal, (None, None))
        return math.isfinite(x) and (lo is None or lo <= x) and (hi is None or x <= hi)

    def _classify_pdo(self, name: str, data: bytes, ts: float) -> Decoded:
        if len(data) != self._lengths[name]:
            if name in ("SENSOR_POS", "SENSOR_AUX"):
                self.bad_length_pdos += 1
                self.last_bad_length = (name, len(data))
            return Decoded(Verdict.BAD_DLC, name, None, ts)
        if name in ("SYNC", "NMT"):
            return Decoded(Verdict.OK, name, {}, ts)
        sc = self.scaling
        if name == "SENSOR_AUX":
            status, spool_raw = unpack_valve_tpdo(data) or (0, 0)
            spool = sc.spool_m(spool_raw)
            if not self._in_range("SENSOR_POS", "Spool", spool):
                return Decoded(Verdict.OUT_OF_RANGE, name, None, ts)
            self.status_word, self._spool_m = status, spool
            self.valve_tpdos += 1
            echo = self._applied[0] if status & (STATE_BITS | BIT_R) == _ACTIVE_STATUS else 0.0
            values = {"CoilCurrent": echo, "LoadPressure": 0.0, "Spool": spool, "StatusWord": status}
            return Decoded(Verdict.OK, name, values, ts)
        if name == "SENSOR_POS":
            position = sc.position_m(unpack_encoder_tpdo(data) or 0)
            sync = self._sync
            if sync is not None and sync == self._pos_sync:  # answered already: no new sample
                return Decoded(Verdict.OK, name, None, ts, sync)
            counter = sync if sync is not None else (self._pos_counter + 1) & 0x0F
            self._pos_sync, self._pos_counter = sync, counter
            rate = self._rate.get(self._ids[name])
            if not self._in_range(name, "Position", position) or (
                rate is not None and not rate[1].check(position, counter)
            ):
                return Decoded(Verdict.OUT_OF_RANGE, name, None, ts)
            return Decoded(Verdict.OK, name, {"Position": position, "Spool": self._spool_m}, ts, counter)
        word, raw = unpack_valve_rpdo(data) or (0, 0)
        active = word & STATE_BITS == _ACTIVE_REQUEST
        values = {
            "CurrentSetpoint": sc.current_a(raw) if active else 0.0,
            "Enable": int(active),
            "ControlWord": word,
        }
        return Decoded(Verdict.OK, name, values, ts)


def _master_ids(valve_node: int, encoder_node: int) -> dict[int, str]:
    """The COB-IDs the master sends or reads → their service (NMT, SYNC, each node's)."""
    ids = {cobid.NMT: "NMT", cobid.SYNC: "SYNC"}
    for node in (valve_node, encoder_node):
        for base, what in (
            (cobid.EMCY, "EMCY"),
            (cobid.TPDO1, "TPDO1"),
            (cobid.TPDO2, "TPDO2"),
            (cobid.RPDO1, "RPDO1"),
            (cobid.SDO_TX, "SDO"),
            (cobid.SDO_RX, "SDO"),
            (cobid.HEARTBEAT, "heartbeat"),
        ):
            ids[base + node] = f"{what} of node {node}"
    return ids


def master_codec(c: Cia408Config, spool_stroke_m: float, dbc: str, ids: CanIds, src: str) -> Cia408Codec:
    """The master's codec for the nodes of ``c`` (their EDS files checked; the position step
    :func:`.check.position_step_nm`, the encoder's until start-up reads it by SDO); a native
    frame on one of the master's COB-IDs is a :class:`ConfigError` naming ``ids.id_base``."""
    from .check import check_nodes, position_step_nm

    valve_od, encoder_od = check_nodes(c, src)
    step_nm = position_step_nm(c, valve_od, encoder_od, src)
    scaling = Scaling(c.full_scale_current_a, spool_stroke_m, step_of_nm(step_nm))
    try:
        codec = Cia408Codec(
            c.valve_node,
            c.encoder_node,
            scaling,
            dbc or None,
            id_base=ids.id_base,
            node_ids={"HEARTBEAT_CTRL": ids.controller_node, "HEARTBEAT_EMU": ids.emulator_node},
            max_delta_counter=ids.max_delta_counter,
            position_from_valve=c.position_source == "valve",
        )
    except FrameIdError as exc:
        raise ConfigError(src, "ids.id_base", str(exc)) from exc
    used = _master_ids(c.valve_node, c.encoder_node)
    for name, can_id in codec.native_ids():
        if can_id in used and name != "HEARTBEAT_CTRL":
            raise ConfigError(src, "ids.id_base", f"{name} at 0x{can_id:03X} is the {used[can_id]}")
    return codec
