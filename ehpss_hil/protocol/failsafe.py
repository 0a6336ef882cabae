"""Why the controller is in fail-safe: the values of CTRL_STATUS ``FailsafeReason`` (the DBC's
VAL_ table), shared by the loop's lifecycle (:mod:`ehpss_hil.runtime.lifecycle`), its watchdog
and the CANopen master's device checks (:mod:`ehpss_hil.protocol.cia408.master`)."""

from __future__ import annotations

from enum import IntEnum


class FailsafeReason(IntEnum):
    """CTRL_STATUS FailsafeReason."""

    NONE = 0
    SENSOR_TIMEOUT = 1
    E2E_ERRORS = 2
    PLAUSIBILITY = 3
    OPERATOR = 4
    #: the loop itself: more periods skipped at once than the predictors bridge, or starved
    LOOP_OVERRUN = 5
    #: a second transmitter: our VALVE_CMD from another node, the emulator's CommandConflict,
    #: a second SENSOR_POS stream (runtime/foreign.py; ``watchdog.on_collision: fault``)
    ID_COLLISION = 6
    #: protocol cia408: the valve's status word left ACTIVE (protocol/cia408/master.py)
    DEVICE_FAULT = 7
    #: protocol cia408: an EMCY with an error code from a node
    EMCY = 8
    #: protocol cia408: a node's heartbeat stopped or shows a state other than OPERATIONAL
    HEARTBEAT_LOST = 9
    #: the bus: frames not sent for ``timeout_cycles`` cycles (interface down, transmit queue
    #: full), bus-off, error-passive, or a burst of error frames (runtime/bushealth.py)
    BUS_ERROR = 10
    #: protocol cia408: a TPDO of a length other than its mapping (CiA 301: not processed; the
    #: node maps it so, or another node transmits on its COB-ID)
    PDO_ERROR = 11
