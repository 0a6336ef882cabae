"""Object indices, NMT codes, the CiA 408 device-control bits, EMCY and SDO abort codes.

The CiA 408 device state machine as the emulated valve implements it (a real valve's manual is
the authority for its own bits): the control word's bits 0…2 (D, H, M) request DISABLED (D),
HOLD (D+H) or DEVICE_MODE_ACTIVE (D+H+M); bit 3 (R) resets a fault on its rising edge. The
status word mirrors the state in the same bits 0…2 and sets bit 3 (ready) when no fault is
latched: FAULT (FAULT_DISABLED) shows D with R clear, FAULT_HOLD shows D+H with R clear.
"""

from __future__ import annotations

import enum

# ---- communication objects (CiA 301) ------------------------------------------------------
DEVICE_TYPE = 0x1000  #: UNSIGNED32: low word the profile number, high word profile-specific
ERROR_REGISTER = 0x1001
#: pre-defined error field (error history): sub 0 the number of errors (write 0 to clear), sub
#: 1… UNSIGNED32 errors, newest first (low word the EMCY error code)
ERROR_HISTORY = 0x1003
DEVICE_NAME = 0x1008
COB_ID_EMCY = 0x1014
CONSUMER_HEARTBEAT = 0x1016  #: sub n: UNSIGNED32 (producer node << 16) | time (ms)
PRODUCER_HEARTBEAT = 0x1017  #: UNSIGNED16 period (ms), 0 = off
#: sub 1: UNSIGNED8, the NMT state a node takes on a communication error (heartbeat of a consumed
#: producer lost, an RPDO event timer elapsed) while OPERATIONAL: one of ErrorBehaviour
ERROR_BEHAVIOUR = 0x1029
ERROR_BEHAVIOUR_COMMUNICATION = 1
IDENTITY = 0x1018  #: sub 1 vendor-ID, 2 product code, 3 revision, 4 serial number
RPDO_COMM, RPDO_MAP = 0x1400, 0x1600
TPDO_COMM, TPDO_MAP = 0x1800, 0x1A00
#: PDO communication parameter sub-indices
PDO_COB_ID, PDO_TRANSMISSION, PDO_INHIBIT, PDO_EVENT_TIMER = 1, 2, 3, 5
#: bit 31 of a PDO COB-ID: the PDO is not valid (off)
PDO_INVALID = 0x8000_0000
#: transmission types: 1…240 synchronous (every n-th SYNC), 254/255 event-driven
PDO_SYNC_MAX = 240

# ---- device profiles -------------------------------------------------------------------------
PROFILE_VALVE = 408  #: CiA 408 fluid power (proportional valves)
PROFILE_ENCODER = 406  #: CiA 406 encoders
ENCODER_ABSOLUTE_LINEAR = 0x0008  #: CiA 406 device type's high word: an absolute linear encoder

# ---- CiA 408 valve objects ----------------------------------------------------------------
CONTROL_WORD = 0x6040  #: UNSIGNED16
STATUS_WORD = 0x6041  #: UNSIGNED16
DEVICE_MODE = 0x6042  #: INTEGER8, 1 = set-point input via the bus
DEVICE_CONTROL_MODE = 0x6043  #: INTEGER8, 1 = spool position control, open loop
VPOC_SETPOINT = 0x6300  #: sub 1: INTEGER16 spool set-point, ±SCALE_100_PERCENT = ±100 %
VPOC_ACTUAL = 0x6301  #: sub 1: INTEGER16 spool actual value, same scaling
VPOC_SUB = 1
VPOC_DEMAND = 0x6311  #: sub 1: INTEGER16 demand value (the set-point after limits and ramp)
VPOC_HOLD_SETPOINT = 0x6314  #: sub 1: INTEGER16 set-point applied in HOLD
VPOC_UPPER_LIMIT = 0x6320  #: sub 1: INTEGER16 upper set-point limit
VPOC_LOWER_LIMIT = 0x6321  #: sub 1: INTEGER16 lower set-point limit
VPOC_RAMP_TYPE = 0x6330  #: INTEGER8: 0 no ramp, RAMP_LINEAR
VPOC_RAMP_TIME = 0x6331  #: sub 1: UNSIGNED16 ms for 100 % (the emulated valve's one ramp time)
RAMP_NONE, RAMP_LINEAR = 0, 1
DEVICE_MODE_SETPOINT_VIA_BUS = 1
CONTROL_MODE_SPOOL_OPEN_LOOP = 1
#: the valve's own spool position loop: the set-point is a spool position (±16384 = ±stroke)
CONTROL_MODE_SPOOL_CLOSED_LOOP = 2
#: control deviation monitoring: deviation (demand − actual, INTEGER16), type (INTEGER8, one of
#: MONITORING_*), delay (UNSIGNED16 ms), threshold (INTEGER16, the symmetric band ±threshold),
#: upper and lower threshold (INTEGER16, the window [lower, upper] of MONITORING_WINDOW)
VPOC_DEVIATION = 0x6350
VPOC_MONITORING_TYPE = 0x6351
VPOC_MONITORING_DELAY = 0x6352
VPOC_MONITORING_THRESHOLD = 0x6353
VPOC_MONITORING_UPPER = 0x6354
VPOC_MONITORING_LOWER = 0x6355
#: 0x6351 values: off; |deviation| against ±0x6353; deviation against [0x6355, 0x6354]
MONITORING_OFF, MONITORING_SYMMETRIC, MONITORING_WINDOW = 0, 1, 2
#: the CiA 408 16-bit value of 100 % (set-point, actual value)
SCALE_100_PERCENT = 16384

#: manufacturer-specific (the project's emulated valve): INTEGER32 cylinder position from the
#: valve's own sensor input, in steps of VALVE_POSITION_STEP_NM; a master may take the position
#: from it instead of a CiA 406 encoder (``cia408.position_source: valve``)
VALVE_POSITION = 0x2100
VALVE_POSITION_STEP_NM = 100

# ---- CiA 406 encoder objects -----------------------------------------------------------
POSITION_VALUE = 0x6004  #: INTEGER32 position in measuring steps
MEASURING_STEP = 0x6005  #: sub 1: UNSIGNED32 measuring step (nm)
OPERATING_PARAMETERS = 0x6000  #: UNSIGNED16 (bit 0 code sequence, bit 2 scaling), as 0x6500 shows
PRESET_VALUE = 0x6003  #: INTEGER32: writing it makes the position value equal to it now
SPEED_VALUE = 0x6030  #: sub 1: INTEGER16 speed in SPEED_LSB_M_S steps (the emulated encoder's unit)
OPERATING_STATUS = 0x6500  #: UNSIGNED16
OFFSET_VALUE = 0x6509  #: INTEGER32: the offset the preset set (steps)
#: the emulated encoder's speed value step (m/s): 0.1 mm/s, ±3.2 m/s in INTEGER16
SPEED_LSB_M_S = 1e-4

# ---- control word / status word bits (CiA 408) -------------------------------------------
BIT_D = 0x0001  #: disabled → enabled electronics (DISABLED)
BIT_H = 0x0002  #: hold
BIT_M = 0x0004  #: device mode active
BIT_R = 0x0008  #: control word: fault reset (rising edge); status word: ready (no fault)
STATE_BITS = BIT_D | BIT_H | BIT_M
#: status word bit 10: the set-point is clipped by the limits 0x6320/0x6321
BIT_LIMIT = 0x0400
#: status word bit 11: the control deviation beyond its threshold for longer than its delay
BIT_DEVIATION = 0x0800


class DeviceState(enum.IntEnum):
    """CiA 408 device states the emulated valve takes (the status word shows each)."""

    NOT_READY = 0  #: after power-on: the electronics not ready, control words not obeyed
    DISABLED = 1
    HOLD = 2
    ACTIVE = 3  #: DEVICE_MODE_ACTIVE: the set-point drives the spool
    FAULT = 4  #: FAULT_DISABLED
    FAULT_HOLD = 5
    INIT = 6  #: initialising (after NOT_READY), control words not obeyed yet
    FAULT_REACTION = 7  #: a fault met: the reaction runs, then FAULT or FAULT_HOLD


#: status word of each state (bits 0…3)
STATUS_OF = {
    DeviceState.NOT_READY: 0,
    DeviceState.DISABLED: BIT_D | BIT_R,
    DeviceState.HOLD: BIT_D | BIT_H | BIT_R,
    DeviceState.ACTIVE: BIT_D | BIT_H | BIT_M | BIT_R,
    DeviceState.FAULT: BIT_D,
    DeviceState.FAULT_HOLD: BIT_D | BIT_H,
    DeviceState.INIT: BIT_R,
    DeviceState.FAULT_REACTION: BIT_D | BIT_H | BIT_M,
}


def state_of_status(word: int) -> DeviceState:
    """The device state a status word shows (its bits 0…3); NOT_READY for any other pattern."""
    low = word & (STATE_BITS | BIT_R)
    for state, bits in STATUS_OF.items():
        if bits == low:
            return state
    return DeviceState.NOT_READY


# ---- NMT (CiA 301) ----------------------------------------------------------------------------
class NmtCommand(enum.IntEnum):
    """Command specifiers of the NMT frame (COB-ID 0x000: [command, node id or 0 = all])."""

    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class ErrorBehaviour(enum.IntEnum):
    """0x1029 values (CiA 301): the NMT state after a communication error in OPERATIONAL."""

    PRE_OPERATIONAL = 0
    NO_CHANGE = 1
    STOPPED = 2


class NmtState(enum.IntEnum):
    """NMT states as the heartbeat's byte carries them."""

    BOOT_UP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


# ---- EMCY (CiA 301) -----------------------------------------------------------------------
EMCY_NO_ERROR = 0x0000  #: error reset / no error
EMCY_COMMUNICATION = 0x8100  #: communication, generic (the valve left NMT OPERATIONAL while enabled)
EMCY_HEARTBEAT = 0x8130  #: life guard or heartbeat error (the master's heartbeat was lost)
EMCY_RPDO_TIMEOUT = 0x8250  #: an RPDO (the set-point) did not arrive within its event timer
EMCY_PDO_LENGTH = 0x8210  #: a PDO not processed: shorter than its mapping
EMCY_SYNC_LENGTH = 0x8240  #: a SYNC with a data length other than the one configured (0: no counter)
#: internal software: the emulated valve's plant stopped (an FMU's step failed); a persistent
#: internal fault, so a reset does not clear it (firmware_sim's ValveNode.internal_fault)
EMCY_INTERNAL_SOFTWARE = 0x6100
ERR_REG_GENERIC = 0x01
ERR_REG_COMMUNICATION = 0x10

# ---- SDO abort codes (CiA 301) -------------------------------------------------------------
ABORT_NOT_IN_OD = 0x0602_0000  #: object does not exist in the object dictionary
ABORT_READ_ONLY = 0x0601_0002  #: attempt to write a read-only object
ABORT_LENGTH = 0x0607_0010  #: data type does not match, length of service parameter does not match
ABORT_RANGE = 0x0609_0030  #: value range of parameter exceeded
ABORT_STATE = 0x0800_0022  #: data cannot be transferred because of the present device state
