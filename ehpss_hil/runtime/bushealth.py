"""Is the bus itself healthy? Evidence that a command cannot reach the valve (reason BUS_ERROR).

What a process sees of its bus failing:

- **its own frames not sent, or nothing received**: python-can raises on a send or a receive
  (``CanOperationError``/``OSError``: ENETDOWN when the interface went down, ENOBUFS when the
  transmit queue is full, a driver error on other interfaces). A cycle in which a send or a
  receive failed is a failed cycle;
  ``watchdog.timeout_cycles`` failed cycles in a row (as many as the sensor may be silent) are a
  bus error: the valve has been without its command for that long.
- **error frames** (SocketCAN delivers them: python-can sets ``CAN_RAW_ERR_FILTER`` to every
  class): the controller going bus-off, error-passive, or a transmit timeout is a bus error at
  once (:data:`SEVERE_CLASSES`); other classes (a protocol violation, a missing ACK, a lost
  arbitration, a transceiver fault) are counted, and :data:`ERROR_FRAME_LIMIT` of them within
  :data:`ERROR_FRAME_WINDOW_CYCLES` cycles are a bus error (one glitch is not).

:class:`BusHealth` latches the evidence as the collision guard does: it holds while evidence
comes, and releases ``recovery_cycles`` quiet cycles later only with ``watchdog.auto_recover``.
Error classes and bits: Linux ``include/uapi/linux/can/error.h``.
"""

from __future__ import annotations

import logging
from collections import deque

import can

from ..config import Watchdog

log = logging.getLogger("ehpss_hil.controller")

#: error.h error classes (in the error frame's CAN ID)
CAN_ERR_TX_TIMEOUT = 0x001
CAN_ERR_LOSTARB = 0x002
CAN_ERR_CRTL = 0x004
CAN_ERR_PROT = 0x008
CAN_ERR_TRX = 0x010
CAN_ERR_ACK = 0x020
CAN_ERR_BUSOFF = 0x040
CAN_ERR_BUSERROR = 0x080
CAN_ERR_RESTARTED = 0x100
#: CAN_ERR_CRTL detail (data[1]): the controller is error-passive (rx or tx)
CAN_ERR_CRTL_PASSIVE = 0x10 | 0x20
#: classes that are a bus error at once: the node cannot (reliably) transmit any more
SEVERE_CLASSES = CAN_ERR_TX_TIMEOUT | CAN_ERR_BUSOFF
#: other error frames: this many within the window is a bus error (a burst, not a glitch)
ERROR_FRAME_LIMIT = 10
ERROR_FRAME_WINDOW_CYCLES = 100
#: a warning: the first failed send, then every this many
WARN_EVERY = 1000


def error_class(msg: can.Message) -> str:
    """A short name for an error frame's class bits (for the log and the summary)."""
    bits = msg.arbitration_id & 0x1FF
    names = [
        n
        for b, n in (
            (CAN_ERR_TX_TIMEOUT, "tx-timeout"),
            (CAN_ERR_LOSTARB, "lost-arbitration"),
            (CAN_ERR_CRTL, "controller"),
            (CAN_ERR_PROT, "protocol"),
            (CAN_ERR_TRX, "transceiver"),
            (CAN_ERR_ACK, "no-ack"),
            (CAN_ERR_BUSOFF, "bus-off"),
            (CAN_ERR_BUSERROR, "bus-error"),
            (CAN_ERR_RESTARTED, "restarted"),
        )
        if bits & b
    ]
    return "+".join(names) or "unspecified"


def is_severe(msg: can.Message) -> bool:
    """Bus-off, a transmit timeout, or the controller error-passive."""
    bits = msg.arbitration_id
    if bits & SEVERE_CLASSES:
        return True
    return bool(bits & CAN_ERR_CRTL and len(msg.data) > 1 and msg.data[1] & CAN_ERR_CRTL_PASSIVE)


class BusHealth:
    """Send failures and error frames of one process's bus; :meth:`update` once per cycle."""

    def __init__(self, wd: Watchdog | None = None) -> None:
        wd = wd or Watchdog()
        self._fail_limit = wd.timeout_cycles
        self._auto_recover = wd.auto_recover
        self._recovery_cycles = wd.recovery_cycles
        self._cycle_failed = False
        self._severe = ""
        self._minor: deque[int] = deque()
        self._cycle = 0
        #: consecutive cycles with a failed send
        self.failed_in_row = 0
        #: counters (JSON-able in :meth:`summary`)
        self.tx_errors = 0
        self.rx_errors = 0
        self.error_frames: dict[str, int] = {}
        self.episodes = 0
        self.quiet_cycles = 0
        self.holding = False
        self.last_cause = ""

    def tx_failed(self, name: str, exc: BaseException) -> None:
        """A frame could not be sent."""
        self.tx_errors += 1
        self._cycle_failed = True
        if self.tx_errors == 1 or self.tx_errors % WARN_EVERY == 0:
            log.warning("%s not sent (%d transmit errors): %s", name, self.tx_errors, exc)

    def rx_failed(self, exc: BaseException) -> None:
        """A receive failed (the interface went down): a failed cycle, as a failed send."""
        self.rx_errors += 1
        self._cycle_failed = True
        if self.rx_errors == 1 or self.rx_errors % WARN_EVERY == 0:
            log.warning("receive failed (%d receive errors): %s", self.rx_errors, exc)

    def error_frame(self, msg: can.Message) -> None:
        """An error frame received."""
        kind = error_class(msg)
        self.error_frames[kind] = self.error_frames.get(kind, 0) + 1
        if is_severe(msg):
            self._severe = kind
        else:
            self._minor.append(self._cycle)

    def update(self, cycle: int) -> bool:
        """Account the cycle that just ended; True while the loop must be in fail-safe for
        BUS_ERROR."""
        self._cycle = cycle
        self.failed_in_row = self.failed_in_row + 1 if self._cycle_failed else 0
        while self._minor and self._minor[0] <= cycle - ERROR_FRAME_WINDOW_CYCLES:
            self._minor.popleft()
        causes = []
        if self.failed_in_row >= self._fail_limit:
            causes.append(f"frames not sent or received for {self.failed_in_row} cycles")
        if self._severe:
            causes.append(f"error frame {self._severe}")
        if len(self._minor) >= ERROR_FRAME_LIMIT:
            causes.append(f"{len(self._minor)} error frames in {ERROR_FRAME_WINDOW_CYCLES} cycles")
        self._cycle_failed = False
        self._severe = ""
        if causes:
            if not self.holding or self.quiet_cycles:
                self.episodes += 1 if not self.holding else 0
                self.last_cause = "; ".join(causes)
            if not self.holding:
                log.error("cycle %d: bus error: %s", cycle, self.last_cause)
            self.holding = True
            self.quiet_cycles = 0
        elif self.holding:
            self.quiet_cycles += 1
            if self._auto_recover and self.quiet_cycles >= self._recovery_cycles:
                self.holding = False
                log.warning("cycle %d: bus healthy for %d cycles", cycle, self.quiet_cycles)
        return self.holding

    def summary(self) -> dict[str, object]:
        """Counters (JSON-able)."""
        return {
            "episodes": self.episodes,
            "tx_errors": self.tx_errors,
            "rx_errors": self.rx_errors,
            "error_frames": dict(self.error_frames),
            "last_cause": self.last_cause,
        }
