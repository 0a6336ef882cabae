"""The controller as the CANopen master of ``protocol: cia408`` (docs/hardware.md).

:class:`MasterSession` is the start-up and the end, through ``canopen``'s master on the loop's
own bus (a notifier thread only while it runs, none during the cycle): wait for each node to
answer (its boot-up or heartbeat awaited between tries), check its identity (0x1000: CiA 408
valve, CiA 406 encoder), configure it by SDO (:mod:`ehpss_hil.protocol.cia408.configure`), NMT
start, OPERATIONAL confirmed in the heartbeat; after the loop, NMT stop.

:class:`CyclicMaster` is the master's part of each cycle, in the loop's thread: the nodes'
heartbeats (consumed, counted in cycles) and EMCY frames (and another producer's SYNCs, counted),
the CiA 408 device drive (control word from the newest status word,
:class:`~ehpss_hil.protocol.cia408.drive.DeviceDrive`), and the
fail-safe reason when a node's heartbeat stops or shows another NMT state (HEARTBEAT_LOST), an
EMCY with an error code arrives once the valve has been ACTIVE (EMCY; before, the drive resets
the fault it reports: the valve may have missed our heartbeat during the start-up) or the
status word leaves ACTIVE (DEVICE_FAULT) or a TPDO's length is not its mapping's (PDO_ERROR);
these latch, and the valve is asked for DISABLED. A cycle without a status word counts for the
loop's watchdog as a cycle without data (:attr:`CyclicMaster.status_fresh`: SENSOR_TIMEOUT,
with the watchdog's own recovery).

**Shutting the valve out.** Plain CANopen PDOs carry no sender and no E2E: while another node
sends the valve's RPDO (or SYNC, or an NMT command), our RPDO asking for DISABLED may be
overwritten by the next foreign one. On a second transmitter (the loop's ID_COLLISION:
:meth:`CyclicMaster.second_transmitter`), a node leaving OPERATIONAL that we did not command or
a lost heartbeat (HEARTBEAT_LOST), or a malformed TPDO (PDO_ERROR), the master also sends, once,
an SDO write of the control word DISABLED (processed while the valve is still OPERATIONAL) and
then NMT Stop of the valve: in STOPPED a CiA 301 node processes no PDO (the rogue's RPDOs are
shut out) and a CiA 408 valve takes its fault reaction. Our own Stop is expected in the valve's
heartbeat from then on, not a failure. With ``sync: follow`` SYNC is not ours: a second
producer shows as more SYNCs than one producer at the loop rate sends
(:class:`~ehpss_hil.protocol.ratewindow.RateWindow` over the last 40 cycles), ID_COLLISION too.

**The error history.** After each EMCY with an error code the master reads the node's error
history 0x1003 by SDO (:class:`~ehpss_hil.protocol.cia408.history.ErrorHistoryReader`: one
expedited upload per cycle, the answers taken from the drain), logs it and reports it in the
summary (``error_history``).
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import can

from ...config import Cia408Config
from ...errors import NodeError
from ..failsafe import FailsafeReason
from ..ratewindow import RateWindow
from . import cobid
from .codec import Cia408Codec
from .configure import configure_encoder, configure_valve
from .cyclic import Scaling, frame, step_of_nm, unpack_emcy, unpack_heartbeat
from .drive import DeviceDrive
from .eds import ENCODER_EDS, VALVE_EDS
from .history import ErrorHistoryReader
from .identity import check_expected, expected_for
from .objects import (
    BIT_D,
    CONTROL_WORD,
    DEVICE_TYPE,
    EMCY_NO_ERROR,
    PROFILE_ENCODER,
    PROFILE_VALVE,
    NmtCommand,
    NmtState,
)
from .sdolog import quiet_sdo_timeouts
from .startup import SDO_TIMEOUT_S, NodeIdentity, check_identity, go_operational, stop_nodes

log = logging.getLogger("ehpss_hil.controller")

#: how long the start-up waits for a node to answer (s): the nodes may boot after us
NODE_WAIT_S = 120.0
#: between two tries, how long it waits for a boot-up or heartbeat of the node (s)
NODE_POLL_S = 1.0
#: a status word from the cycle before still counts as fresh: the valve's TPDO and the
#: encoder's, sent back to back, may fall on either side of a drain
STATUS_SLACK_CYCLES = 1
#: the start-up notifier's read timeout (s): how long stopping it may take
NOTIFIER_CYCLE_S = 0.05
#: the fail-safe reasons on which the master shuts the valve out (module docstring)
SHUT_OUT_REASONS = frozenset(
    (FailsafeReason.ID_COLLISION, FailsafeReason.HEARTBEAT_LOST, FailsafeReason.PDO_ERROR)
)
#: SDO expedited download of 2 bytes (CiA 301 command specifier: ccs 1, e 1, s 1, n 2)
SDO_DOWNLOAD_2_BYTES = 0x2B


def sdo_write_u16(node: int, index: int, sub: int, value: int) -> can.Message:
    """An SDO expedited download request of an UNSIGNED16 to ``node`` (its answer is not
    awaited: the loop does not block)."""
    data = bytes([SDO_DOWNLOAD_2_BYTES, index & 0xFF, index >> 8, sub, value & 0xFF, value >> 8, 0, 0])
    return frame(cobid.SDO_RX + node, data)


class MasterSession:
    """``canopen``'s Network on ``bus`` for the start-up and the NMT stop of the nodes of ``c``;
    ``wait_s``: how long a node may take to answer (s)."""

    def __init__(self, bus: can.BusABC, c: Cia408Config, wait_s: float = NODE_WAIT_S) -> None:
        import canopen

        self.c = c
        self.wait_s = wait_s
        self.bus = bus
        self.net = canopen.Network(bus)
        self.valve = self.net.add_node(c.valve_node, str(c.valve_eds or VALVE_EDS))
        #: the CiA 406 encoder (None: the position comes from the valve)
        self.encoder = (
            self.net.add_node(c.encoder_node, str(c.encoder_eds or ENCODER_EDS))
            if c.position_source == "encoder"
            else None
        )
        self.identities: tuple[NodeIdentity, ...] = ()

    def start(self, codec: Cia408Codec) -> tuple[NodeIdentity, ...]:
        """Start-up of the nodes (module docstring); the encoder's measuring step goes into
        ``codec``'s scaling. Raises :class:`NodeError`."""
        self.net.notifier = can.Notifier(self.bus, self.net.listeners, NOTIFIER_CYCLE_S)
        enc = self.encoder
        with quiet_sdo_timeouts():  # each time-out is handled here (protocol/cia408/sdolog.py)
            try:
                ids = self._identify(enc)
                configure_valve(self.valve, self.c)
                if enc is not None:
                    step_nm = configure_encoder(enc, self.c)
                    sc = codec.scaling
                    codec.scaling = Scaling(sc.full_scale_current_a, sc.spool_stroke_m, step_of_nm(step_nm))
                go_operational(self.valve, "valve")
                if enc is not None:
                    go_operational(enc, "encoder")
            finally:
                self.net.notifier.stop(NOTIFIER_CYCLE_S * 20)
                self.net.notifier = None
        self.identities = tuple(ids)
        log.info("cia408 start-up: %s", "; ".join(i.text() for i in ids))
        return self.identities

    def _identify(self, enc: Any) -> list[NodeIdentity]:
        """Each node awaited, its profile and its identity against the config checked."""
        ids = []
        nodes = ((self.valve, "valve", PROFILE_VALVE), (enc, "encoder", PROFILE_ENCODER))
        for node, role, _ in nodes:
            if node is not None:
                _await_node(node, role, self.wait_s)
        for node, role, profile in nodes:
            if node is not None:
                ids.append(check_identity(node, profile, role))
                check_expected(ids[-1], expected_for(self.c, role), role)
        return ids

    def stop(self) -> None:
        """NMT stop of the nodes (nothing awaited)."""
        stop_nodes(*(n for n in (self.valve, self.encoder) if n is not None))


def _await_node(node: Any, role: str, wait_s: float) -> None:
    """Until ``node`` answers an SDO read of 0x1000 (a node whose heartbeat is off still does),
    each try after its boot-up or heartbeat or :data:`NODE_POLL_S`; NodeError after ``wait_s``
    (s)."""
    from canopen.nmt import NmtError
    from canopen.sdo import SdoCommunicationError

    node.sdo.RESPONSE_TIMEOUT = SDO_TIMEOUT_S
    end = time.monotonic() + wait_s
    waiting = False
    while True:
        try:  # a booting node's boot-up message, a running one's heartbeat: ask at once
            node.nmt.wait_for_heartbeat(NODE_POLL_S)
        except NmtError:
            pass  # none: its heartbeat may be off
        try:
            node.sdo.upload(DEVICE_TYPE, 0)
            return
        except SdoCommunicationError as exc:
            if time.monotonic() > end:
                raise NodeError(f"{role} node {node.id}: no answer within {wait_s:g} s") from exc
            if not waiting:
                log.info("%s node %d: no SDO answer yet; waiting up to %g s", role, node.id, wait_s)
                waiting = True


class CyclicMaster:
    """The master's work in each cycle of the loop (module docstring); ``rate_hz`` the loop's."""

    def __init__(self, codec: Cia408Codec, c: Cia408Config, rate_hz: float) -> None:
        self.codec = codec
        #: the loop sends SYNC after each command (else another node produces it)
        self.produces_sync = c.sync == "produce"
        #: SYNC frames received from another producer (``sync: follow``), per cycle over a window
        self.syncs_seen = 0
        self._sync_rate = RateWindow()
        #: a valve TPDO (a status word) arrived in this cycle or the one before: the loop's
        #: watchdog counts a cycle without one as a cycle without data
        self.status_fresh = False
        self._valve_tpdos = 0
        self._status_cycle = -STATUS_SLACK_CYCLES - 1
        self.drive = DeviceDrive()
        nodes = (c.valve_node, c.encoder_node) if c.position_source == "encoder" else (c.valve_node,)
        self._hb_ids = {cobid.HEARTBEAT + n: n for n in nodes}
        self._valve_node = c.valve_node
        #: the NMT state each node's heartbeat should show (we commanded it)
        self._expected = dict.fromkeys(nodes, NmtState.OPERATIONAL)
        #: frames the loop sends after this cycle's command: (name, frame)
        self._outbox: list[tuple[str, can.Message]] = []
        self.shut_out = False
        #: the error history of the node that sent the last EMCY
        self.history = ErrorHistoryReader()
        self._emcy_ids = {cobid.EMCY + n: n for n in nodes}
        #: cycles without a node's heartbeat after which it is lost
        self.hb_timeout_cycles = max(1, math.ceil(c.node_heartbeat_timeout_ms * 1e-3 * rate_hz))
        #: the nodes whose heartbeat is watched (none when the start-up turns heartbeats off)
        self._hb_cycle = dict.fromkeys(nodes if c.heartbeat_time_ms else (), 0)
        self._cycle = 0
        #: the fail-safe reason (the first one latches) and the cycle it came in
        self.reason: FailsafeReason | None = None
        self.fault_cycle: int | None = None
        self.fault_text = ""
        #: the last EMCY with an error code: (node, code, error register), and how many came
        self.emcy: tuple[int, int, int] | None = None
        self.emcy_frames = 0
        self._pending: tuple[FailsafeReason, str] | None = None

    @property
    def ready(self) -> bool:
        """The valve is ACTIVE and nothing failed: the controller may start."""
        return self.reason is None and self.drive.active

    def on_frame(self, msg: can.Message) -> None:
        """A received frame the loop does not consume (heartbeats and EMCY of the nodes are used)."""
        fid = msg.arbitration_id
        if cobid.SDO_TX < fid <= cobid.SDO_TX + cobid.NODE_MAX:
            reads = self.history.reads
            if self.history.on_response(fid, bytes(msg.data)) and self.history.reads != reads:
                codes = ", ".join(f"0x{c:04X}" for c in self.history.codes) or "empty"
                log.warning("node %d: error history (newest first): %s", self.history.node, codes)
            return
        if fid == cobid.SYNC:
            self.syncs_seen += 1
            self._sync_rate.add(self._cycle + 1)
            self.codec.sync_seen(self._cycle + 1)  # the cycle that drains it
            return
        node = self._hb_ids.get(fid)
        if node is not None:
            self._hb_cycle[node] = self._cycle + 1  # the cycle that drains it (the next update)
            state = unpack_heartbeat(bytes(msg.data))
            if state is not self._expected[node]:
                shown = state.name if state is not None else bytes(msg.data).hex()
                self._heard(FailsafeReason.HEARTBEAT_LOST, f"node {node}: heartbeat shows {shown}")
            return
        node = self._emcy_ids.get(fid)
        if node is not None:
            e = unpack_emcy(bytes(msg.data))
            if e is not None and e[0] != EMCY_NO_ERROR:
                self.emcy = (node, e[0], e[1])
                self.emcy_frames += 1
                self.history.start(node)
                text = f"node {node}: EMCY 0x{e[0]:04X} (error register 0x{e[1]:02X})"
                if self.drive.was_active:
                    self._heard(FailsafeReason.EMCY, text)
                else:  # e.g. our heartbeat missed during the start-up: the drive resets it
                    log.warning("%s before the valve was ACTIVE: reset by the device drive", text)

    def update(self, cycles: int) -> FailsafeReason | None:
        """Before this cycle's command: heartbeat timeouts, the control word from the newest
        status word; returns the fail-safe reason (None: none)."""
        self._cycle = cycles
        if self._pending is not None:
            self._fail(*self._pending)
        for node, seen in self._hb_cycle.items():
            if cycles - seen > self.hb_timeout_cycles:
                self._fail(
                    FailsafeReason.HEARTBEAT_LOST, f"node {node}: no heartbeat for {cycles - seen} cycles"
                )
        if self.codec.valve_tpdos != self._valve_tpdos:
            self._valve_tpdos, self._status_cycle = self.codec.valve_tpdos, cycles
        self.status_fresh = cycles - self._status_cycle <= STATUS_SLACK_CYCLES
        self.codec.control_word = self.drive.update(self.codec.status_word)
        if self.drive.left_active is not None:
            self._fail(
                FailsafeReason.DEVICE_FAULT,
                f"valve status word 0x{self.codec.status_word:04X}: {self.drive.left_active.name}",
            )
        elif self.drive.gave_up:
            self._fail(FailsafeReason.DEVICE_FAULT, "valve fault persists after the fault resets")
        if not self.produces_sync and self._sync_rate.total > self._sync_rate.bound():
            self.second_transmitter(
                f"{self._sync_rate.total} SYNCs in {len(self._sync_rate)} cycles: a second producer"
            )
        if self.codec.bad_length_pdos:
            name, length = self.codec.last_bad_length
            self._fail(FailsafeReason.PDO_ERROR, f"{name} TPDO of {length} bytes, not its mapping's")
        return self.reason

    def second_transmitter(self, cause: str) -> None:
        """The loop saw another transmitter of our frames (ID_COLLISION): shut the valve out."""
        self._fail(FailsafeReason.ID_COLLISION, cause)
        self._shut_out()

    def take_frames(self) -> list[tuple[str, can.Message]]:
        """The frames to send after this cycle's command (and forget them)."""
        req = self.history.take_request()
        out = [("SDO", req)] if req is not None else []
        out, self._outbox = out + self._outbox, []
        return out

    def _shut_out(self) -> None:
        """Once: SDO control word DISABLED, then NMT Stop of the valve (module docstring)."""
        if self.shut_out:
            return
        self.shut_out = True
        node = self._valve_node
        self._expected[node] = NmtState.STOPPED
        log.error("cycle %d: cia408 master: valve %d shut out (SDO DISABLED, NMT Stop)", self._cycle, node)
        self._outbox += [
            ("SDO", sdo_write_u16(node, CONTROL_WORD, 0, BIT_D)),
            ("NMT", self.codec.encode("NMT", {"Command": NmtCommand.STOP, "Node": node})),
        ]

    def _heard(self, reason: FailsafeReason, text: str) -> None:
        """A failure in a received frame, taken by the next :meth:`update` (the first one)."""
        if self._pending is None:
            self._pending = (reason, text)

    def _fail(self, reason: FailsafeReason, text: str) -> None:
        if self.reason is not None:
            return
        self.reason, self.fault_cycle, self.fault_text = reason, self._cycle, text
        log.error("cycle %d: cia408 master: %s -> %s", self._cycle, text, reason.name)
        self.drive.disable()
        self.codec.control_word = self.drive.control_word
        if reason in SHUT_OUT_REASONS:
            self._shut_out()

    def stop(self) -> None:
        """The stop sequence's control word: DISABLED (the loop then sends set-point 0)."""
        self.drive.disable()
        self.codec.control_word = self.drive.control_word

    def device_values(self) -> dict[str, int]:
        """CTRL_DEVICE's signals: the last EMCY (node, code, error register; 0 = none) and the
        valve's status word."""
        node, code, register = self.emcy if self.emcy is not None else (0, 0, 0)
        return {
            "EmcyNode": node,
            "EmcyCode": code,
            "ErrorRegister": register,
            "StatusWord": self.codec.status_word,
        }

    def summary(self) -> dict[str, Any]:
        """Counters and the fault (JSON-able)."""
        return {
            "valve_state": self.drive.state.name,
            "control_word": self.codec.control_word,
            "status_word": self.codec.status_word,
            "fault_reason": self.reason.name if self.reason is not None else None,
            "fault_cycle": self.fault_cycle,
            "fault": self.fault_text,
            "emcy": None
            if self.emcy is None
            else {"node": self.emcy[0], "code": self.emcy[1], "register": self.emcy[2]},
            "emcy_frames": self.emcy_frames,
            "sync": "produced" if self.produces_sync else f"followed ({self.syncs_seen} seen)",
            "fault_resets": self.drive.fault_resets,
            "shut_out": self.shut_out,
            "error_history": {"node": self.history.node, "codes": self.history.codes}
            if self.history.reads
            else None,
            "bad_length_pdos": self.codec.bad_length_pdos,
        }
