"""One emulated CANopen slave (CiA 301): NMT, SDO server, PDOs on SYNC, heartbeat, EMCY.

Everything runs in the emulator's loop, on its clock: the loop hands each received frame to
:meth:`CanopenSlave.on_frame`, each SYNC to :meth:`CanopenSlave.on_sync` and calls
:meth:`CanopenSlave.tick` once per period with the plant time; frames go out through the
``send`` callable the loop gives. No timer thread: the heartbeat, the heartbeat consumer and the
RPDO timeout are counted in loop time.

The SDO protocol (expedited and segmented transfers, abort frames) is ``canopen``'s own
``SdoServer``, served by this node's :class:`~.store.ObjectStore` instead of a ``LocalNode``:
``LocalNode`` brings an NMT slave that starts its heartbeat on a library timer thread, and the
emulator keeps every periodic frame in its own loop.

A profile (:mod:`.valve`, :mod:`.encoder`) subclasses it and fills in the hooks.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from typing import Any

from canopen.sdo import SdoAbortedError, SdoServer

from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.objects import (
    ABORT_RANGE,
    ABORT_STATE,
    CONSUMER_HEARTBEAT,
    EMCY_PDO_LENGTH,
    EMCY_SYNC_LENGTH,
    ERR_REG_COMMUNICATION,
    ERR_REG_GENERIC,
    ERROR_BEHAVIOUR,
    ERROR_BEHAVIOUR_COMMUNICATION,
    ERROR_HISTORY,
    ERROR_REGISTER,
    PDO_COB_ID,
    PDO_EVENT_TIMER,
    PDO_INVALID,
    PDO_SYNC_MAX,
    PDO_TRANSMISSION,
    PRODUCER_HEARTBEAT,
    RPDO_COMM,
    RPDO_MAP,
    TPDO_COMM,
    TPDO_MAP,
    ErrorBehaviour,
    NmtCommand,
    NmtState,
)

from .pdo import PdoMapping, check_entry, read_mapping
from .store import Key, ObjectStore

log = logging.getLogger("firmware_sim")

Send = Callable[[int, bytes], object]  #: send one frame (COB-ID, data); the result is unused
#: PDOs of the predefined set this emulator serves per direction
PDO_COUNT = 4
_COMM_LO, _COMM_HI = 0x1000, 0x1FFF
#: loop times are k·Ts and the heartbeat schedule sums ms: compare with this slack (s)
_TIME_EPS_S = 1e-9


class _SdoLink:
    """What ``canopen``'s SDO server needs of a network: ``send_message``."""

    def __init__(self, send: Send) -> None:
        self.send_message = send


class CanopenSlave:
    """A CANopen node ``node_id`` with object dictionary ``od``; ``overrides``: power-on values
    that replace EDS defaults (the emulator config's heartbeat time, …)."""

    def __init__(self, node_id: int, od: Any, send: Send, overrides: dict[Key, int] | None = None) -> None:
        self.node_id = node_id
        self.store = ObjectStore(od, overrides)
        self.store.on_write = self._on_sdo_write
        self._send = send
        self.sdo = SdoServer(cobid.SDO_RX + node_id, cobid.SDO_TX + node_id, self.store)  # type: ignore[arg-type]
        self.sdo.network = _SdoLink(send)  # type: ignore[assignment]
        self._tpdo_comm = [i for i in range(TPDO_COMM, TPDO_COMM + PDO_COUNT) if i in od]
        self._rpdo_comm = [i for i in range(RPDO_COMM, RPDO_COMM + PDO_COUNT) if i in od]
        self.nmt = NmtState.BOOT_UP
        self.sdo_requests = 0
        self.emcy_sent = 0
        self.rpdos = 0
        self.tpdos = 0
        self._tpdos: list[tuple[int, int, PdoMapping]] = []  # (COB-ID, transmission type, mapping)
        self._rpdos: dict[int, tuple[int, PdoMapping]] = {}  # COB-ID → (comm index, mapping)
        self._syncs = 0
        self._t_s = 0.0
        self._next_hb_s = 0.0
        self._hb_seen: dict[int, float] = {}  # producer node → last heartbeat (loop time, s)
        self._hb_lost: set[int] = set()
        self._rpdo_seen: dict[int, float] = {}  # RPDO comm index → last reception (s)
        self._rpdo_late: set[int] = set()
        self._rpdo_short: set[int] = set()  # RPDOs whose last frame was shorter than mapped
        self._sync_bad = False  # the last SYNC had a data length other than 0
        #: frames refused for their length: RPDOs shorter than mapped, SYNCs with data
        self.bad_length_frames = 0

    # ---- NMT ------------------------------------------------------------------------------------
    def boot(self, t_s: float) -> None:
        """Power-on: every object to its power-on value, boot-up message, PRE-OPERATIONAL."""
        self._t_s = t_s
        self.store.reset(0x0000, 0xFFFF)
        self.reset_application()
        self._boot_up(t_s)

    def _boot_up(self, t_s: float) -> None:
        self._hb_seen.clear()
        self._hb_lost.clear()
        self._rpdo_seen.clear()
        self._rpdo_late.clear()
        self._tpdos, self._rpdos = [], {}
        self._send(cobid.HEARTBEAT + self.node_id, bytes([NmtState.BOOT_UP]))
        self._set_nmt(NmtState.PRE_OPERATIONAL)
        self._next_hb_s = t_s + self._hb_period_s()

    def _set_nmt(self, state: NmtState) -> None:
        was = self.nmt
        if state != was:
            log.info("node %d: NMT %s -> %s", self.node_id, was.name, state.name)
        if state == NmtState.OPERATIONAL and was != NmtState.OPERATIONAL:
            self._build_pdos()
        self.nmt = state
        if was == NmtState.OPERATIONAL and state != NmtState.OPERATIONAL:
            self.on_left_operational()

    def communication_error(self) -> None:
        """A communication error (a consumed heartbeat lost, an RPDO event timer elapsed) while
        OPERATIONAL: the NMT state 0x1029.1 names (CiA 301; no 0x1029: no change)."""
        key = (ERROR_BEHAVIOUR, ERROR_BEHAVIOUR_COMMUNICATION)
        if self.nmt != NmtState.OPERATIONAL or key not in self.store.values:
            return
        behaviour = int(self.store.values[key])
        if behaviour == ErrorBehaviour.PRE_OPERATIONAL:
            self._set_nmt(NmtState.PRE_OPERATIONAL)
        elif behaviour == ErrorBehaviour.STOPPED:
            self._set_nmt(NmtState.STOPPED)

    def _on_nmt(self, data: bytes) -> None:
        if len(data) < 2 or data[1] not in (0, self.node_id):
            return
        try:
            cmd = NmtCommand(data[0])
        except ValueError:
            return
        if cmd == NmtCommand.START:
            self._set_nmt(NmtState.OPERATIONAL)
        elif cmd == NmtCommand.STOP:
            self._set_nmt(NmtState.STOPPED)
        elif cmd == NmtCommand.ENTER_PRE_OPERATIONAL:
            self._set_nmt(NmtState.PRE_OPERATIONAL)
        elif cmd == NmtCommand.RESET_NODE:
            self.store.reset(0x0000, 0xFFFF)
            self.reset_application()
            self._boot_up(self._t_s)
        else:  # reset communication: the communication objects only
            self.store.reset(_COMM_LO, _COMM_HI)
            self._boot_up(self._t_s)

    # ---- frames -------------------------------------------------------------------------------
    def on_frame(self, can_id: int, data: bytes, t_s: float) -> bool:
        """Handle one received frame (not SYNC) at loop time ``t_s``; True when it was for this
        node (NMT, its SDO requests, its RPDOs, a heartbeat it consumes)."""
        self._t_s = t_s
        if can_id == cobid.NMT:
            self._on_nmt(data)
            return True
        if can_id == self.sdo.rx_cobid:
            if self.nmt in (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL) and data:
                self.sdo_requests += 1
                self.sdo.on_request(can_id, bytearray(data), t_s)
            return True
        if cobid.HEARTBEAT < can_id <= cobid.HEARTBEAT + cobid.NODE_MAX:
            producer = can_id - cobid.HEARTBEAT
            if producer in self._consumed():
                self._hb_seen[producer] = t_s
                self._hb_lost.discard(producer)
                return True
            return False
        rpdo = self._rpdos.get(can_id)
        if rpdo is not None and self.nmt == NmtState.OPERATIONAL:
            comm, mapping = rpdo
            values = mapping.unpack(data)
            if values is None:  # not processed (CiA 301): EMCY once per run of short frames
                self.bad_length_frames += 1
                if comm not in self._rpdo_short:
                    self._rpdo_short.add(comm)
                    log.warning(
                        "node %d: RPDO 0x%03X of %d bytes, shorter than mapped",
                        self.node_id,
                        can_id,
                        len(data),
                    )
                    self.send_emcy(EMCY_PDO_LENGTH, ERR_REG_GENERIC | ERR_REG_COMMUNICATION)
            else:
                self._rpdo_short.discard(comm)
                self.rpdos += 1
                self._rpdo_seen[comm] = t_s
                self._rpdo_late.discard(comm)
                self.on_rpdo(values)
            return True
        return False

    def on_sync(self, length: int = 0) -> None:
        """A SYNC of ``length`` data bytes: in OPERATIONAL, each synchronous TPDO due on this
        SYNC goes out now. The nodes have no SYNC counter (0x1019): a SYNC with data is not
        processed, and the first of a run of them is reported (EMCY 0x8240, CiA 301)."""
        if self.nmt != NmtState.OPERATIONAL:
            return
        if length:
            self.bad_length_frames += 1
            if not self._sync_bad:
                self._sync_bad = True
                log.warning("node %d: SYNC with %d data bytes", self.node_id, length)
                self.send_emcy(EMCY_SYNC_LENGTH, ERR_REG_GENERIC | ERR_REG_COMMUNICATION)
            return
        self._sync_bad = False
        self._syncs += 1
        for can_id, every, mapping in self._tpdos:
            if self._syncs % every == 0:
                self._send(can_id, mapping.pack(self.store))
                self.tpdos += 1

    def send_emcy(self, code: int, register: int) -> None:
        """An EMCY frame (0x080 + node): error code, error register (0x1001, stored), 5 zero
        bytes; sent in PRE-OPERATIONAL and OPERATIONAL (CiA 301). An error code other than 0
        enters the error history 0x1003 in every state."""
        self.store.set(ERROR_REGISTER, 0, register)
        if code:
            self._record_error(code)
        if self.nmt in (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL):
            self._send(cobid.EMCY + self.node_id, struct.pack("<HB5x", code, register))
            self.emcy_sent += 1

    def _record_error(self, code: int) -> None:
        """The error history 0x1003: ``code`` at sub 1, the older ones one down, sub 0 the
        number held (at most the EDS's sub-indices)."""
        od = self.store.object_dictionary
        if ERROR_HISTORY not in od:
            return
        size = len(od[ERROR_HISTORY]) - 1
        held = [int(self.store.get(ERROR_HISTORY, s)) for s in range(1, size + 1)]
        for sub, value in enumerate([code & 0xFFFF, *held][:size], start=1):
            self.store.set(ERROR_HISTORY, sub, value)
        self.store.set(ERROR_HISTORY, 0, min(size, int(self.store.get(ERROR_HISTORY, 0)) + 1))

    # ---- time -------------------------------------------------------------------------------
    def _hb_period_s(self) -> float:
        return int(self.store.get(PRODUCER_HEARTBEAT, 0)) * 1e-3

    def _consumed(self) -> dict[int, float]:
        """Heartbeat producers this node monitors → their timeout (s), from 0x1016."""
        out: dict[int, float] = {}
        if CONSUMER_HEARTBEAT not in self.store.object_dictionary:
            return out
        for sub in range(1, int(self.store.get(CONSUMER_HEARTBEAT, 0)) + 1):
            entry = int(self.store.get(CONSUMER_HEARTBEAT, sub))
            node, ms = (entry >> 16) & 0x7F, entry & 0xFFFF
            if node and ms:
                out[node] = ms * 1e-3
        return out

    def tick(self, t_s: float) -> None:
        """Once per period at loop time ``t_s`` (s): heartbeat producer, heartbeat consumer and
        RPDO event-timer checks (each loss reported once, through the hooks)."""
        self._t_s = t_s
        period = self._hb_period_s()
        if period > 0.0 and self.nmt != NmtState.BOOT_UP and t_s >= self._next_hb_s - _TIME_EPS_S:
            self._send(cobid.HEARTBEAT + self.node_id, bytes([self.nmt]))
            self._next_hb_s = max(self._next_hb_s + period, t_s - period)
        elif period == 0.0:
            self._next_hb_s = t_s
        for node, timeout in self._consumed().items():
            seen = self._hb_seen.get(node)
            if seen is not None and node not in self._hb_lost and t_s - seen > timeout:
                self._hb_lost.add(node)
                log.warning("node %d: heartbeat of node %d lost at t=%.4f s", self.node_id, node, t_s)
                self.on_heartbeat_lost(node)
        if self.nmt == NmtState.BOOT_UP:
            return
        for comm in self._rpdo_comm:  # in every NMT state: STOPPED processes no RPDO
            timer_s = int(self.store.values.get((comm, PDO_EVENT_TIMER), 0)) * 1e-3
            seen = self._rpdo_seen.get(comm)
            if timer_s > 0.0 and seen is not None and comm not in self._rpdo_late and t_s - seen > timer_s:
                self._rpdo_late.add(comm)
                log.warning("node %d: RPDO 0x%X timed out at t=%.4f s", self.node_id, comm, t_s)
                self.on_rpdo_timeout(comm)

    # ---- PDO configuration ------------------------------------------------------------------
    def _build_pdos(self) -> None:
        """The PDOs as their communication and mapping objects stand (at NMT start)."""
        st = self.store
        self._tpdos = []
        for comm in self._tpdo_comm:
            cob, kind = int(st.get(comm, PDO_COB_ID)), int(st.get(comm, PDO_TRANSMISSION))
            mapping = read_mapping(st, TPDO_MAP + comm - TPDO_COMM)
            if not cob & PDO_INVALID and 1 <= kind <= PDO_SYNC_MAX and mapping.variables:
                self._tpdos.append((cob & 0x7FF, kind, mapping))
        self._rpdos = {}
        for comm in self._rpdo_comm:
            cob = int(st.get(comm, PDO_COB_ID))
            mapping = read_mapping(st, RPDO_MAP + comm - RPDO_COMM)
            if not cob & PDO_INVALID and mapping.variables:
                self._rpdos[cob & 0x7FF] = (comm, mapping)
        self._syncs = 0

    def _on_sdo_write(self, index: int, sub: int, value: Any) -> None:
        """Checks of an SDO write before it is stored: PDO mappings change only outside
        OPERATIONAL and name mappable objects; then the profile's own checks."""
        is_map = RPDO_MAP <= index < RPDO_MAP + PDO_COUNT or TPDO_MAP <= index < TPDO_MAP + PDO_COUNT
        is_comm = RPDO_COMM <= index < RPDO_COMM + PDO_COUNT or TPDO_COMM <= index < TPDO_COMM + PDO_COUNT
        if (
            is_map or (is_comm and sub in (PDO_COB_ID, PDO_TRANSMISSION))
        ) and self.nmt == NmtState.OPERATIONAL:
            raise SdoAbortedError(ABORT_STATE)
        if is_map and sub > 0:
            check_entry(self.store, int(value))
        if index == ERROR_HISTORY:  # sub 0: only 0 may be written, which clears the history
            if int(value) != 0:
                raise SdoAbortedError(ABORT_RANGE)
            for s in range(1, len(self.store.object_dictionary[ERROR_HISTORY])):
                self.store.set(ERROR_HISTORY, s, 0)
        self.on_object_write(index, sub, value)

    # ---- profile hooks ------------------------------------------------------------------------
    def reset_application(self) -> None:
        """Power-on / reset node: the profile's own state back to its start."""

    def on_rpdo(self, values: list[tuple[Any, Any]]) -> None:
        """A received RPDO's mapped ``(variable, value)`` pairs (already stored by the profile)."""
        for var, value in values:
            self.store.set(var.index, var.subindex, value)

    def on_object_write(self, index: int, sub: int, value: Any) -> None:
        """An SDO write about to be stored; raise ``SdoAbortedError`` to refuse it."""

    def on_heartbeat_lost(self, producer: int) -> None:
        """The heartbeat of node ``producer`` (0x1016) stopped."""

    def on_rpdo_timeout(self, comm_index: int) -> None:
        """No RPDO within its event timer (0x1400 + n, sub 5), in any NMT state but boot-up."""

    def on_left_operational(self) -> None:
        """The node left NMT OPERATIONAL (to STOPPED or PRE-OPERATIONAL): no RPDO is processed
        from now on."""
