"""The master's cyclic CANopen frames, as bytes: SYNC, the valve's RPDO 1, the TPDOs of the valve
and the encoder, EMCY and heartbeat; and the CiA 408 / CiA 406 scalings to SI units.

The PDO layouts are the ones the master's start-up writes by SDO (:mod:`.configure`), equal to
the shipped EDS defaults:

* valve RPDO 1 (0x200 + n): control word 0x6040 (UNSIGNED16), spool set-point 0x6300.1
  (INTEGER16, ±16384 = ±100 % of ``full_scale_current_a``);
* valve TPDO 1 (0x180 + n, every SYNC): status word 0x6041 (UNSIGNED16), spool actual value
  0x6301.1 (INTEGER16, ±16384 = ±100 % of the spool stroke);
* encoder TPDO 1 (0x180 + n, every SYNC): position value 0x6004 (INTEGER32, measuring steps of
  0x6005.1 nm).

Pure functions and one frozen dataclass: no bus, no clock.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import can

from . import cobid
from .objects import SCALE_100_PERCENT, NmtState

#: the packings of the PDOs above (little-endian, CiA 301)
VALVE_RPDO = struct.Struct("<Hh")
VALVE_TPDO = struct.Struct("<Hh")
ENCODER_TPDO = struct.Struct("<i")
EMCY = struct.Struct("<HB5x")
#: NMT (COB-ID 0x000): command specifier, node id (0: all)
NMT_FRAME = struct.Struct("<BB")
_INT16_MAX = 32767
_NM = 1e-9


@dataclass(frozen=True)
class Scaling:
    """The SI value of the process data's integers: ``full_scale_current_a`` (A) is the coil
    current of a +100 % set-point, ``spool_stroke_m`` (m) the spool travel of a +100 % actual
    value, ``step_m`` (m) one encoder measuring step."""

    full_scale_current_a: float
    spool_stroke_m: float
    step_m: float

    @property
    def current_lsb_a(self) -> float:
        """One set-point step (A)."""
        return self.full_scale_current_a / SCALE_100_PERCENT

    @property
    def spool_lsb_m(self) -> float:
        """One spool actual-value step (m)."""
        return self.spool_stroke_m / SCALE_100_PERCENT

    def setpoint_raw(self, current_a: float) -> int:
        """The set-point (±16384 = ±100 %) of a coil current (A), rounded and clipped to ±100 %."""
        raw = round(current_a / self.current_lsb_a)
        return max(-SCALE_100_PERCENT, min(SCALE_100_PERCENT, raw))

    def current_a(self, setpoint_raw: int) -> float:
        """The coil current (A) of a set-point."""
        return setpoint_raw * self.current_lsb_a

    def spool_raw(self, spool_m: float) -> int:
        """The spool actual value of a spool position (m), clipped to INTEGER16."""
        return max(-_INT16_MAX, min(_INT16_MAX, round(spool_m / self.spool_lsb_m)))

    def spool_m(self, raw: int) -> float:
        """The spool position (m) of an actual value."""
        return raw * self.spool_lsb_m

    def position_raw(self, position_m: float) -> int:
        """The encoder's position value (steps) of a position (m), clipped to INTEGER32."""
        return max(-(2**31 - 1), min(2**31 - 1, round(position_m / self.step_m)))

    def position_m(self, steps: int) -> float:
        """The position (m) of a position value."""
        return steps * self.step_m


def step_of_nm(step_nm: int) -> float:
    """The measuring step 0x6005.1 (nm) in m."""
    return step_nm * _NM


def frame(can_id: int, data: bytes, timestamp_s: float = 0.0) -> can.Message:
    """A classic 11-bit data frame."""
    return can.Message(
        arbitration_id=can_id, is_extended_id=False, data=data, dlc=len(data), timestamp=timestamp_s
    )


def sync_frame(timestamp_s: float = 0.0) -> can.Message:
    """SYNC (0x080) without a counter."""
    return frame(cobid.SYNC, b"", timestamp_s)


def valve_rpdo(node: int, control_word: int, setpoint_raw: int, timestamp_s: float = 0.0) -> can.Message:
    """The valve's RPDO 1: control word and set-point."""
    return frame(cobid.RPDO1 + node, VALVE_RPDO.pack(control_word & 0xFFFF, setpoint_raw), timestamp_s)


def unpack_valve_rpdo(data: bytes) -> tuple[int, int] | None:
    """(control word, set-point) of the valve's RPDO 1; None when it is too short."""
    return VALVE_RPDO.unpack_from(data) if len(data) >= VALVE_RPDO.size else None


def valve_tpdo(node: int, status_word: int, spool_raw: int, timestamp_s: float = 0.0) -> can.Message:
    """The valve's TPDO 1: status word and spool actual value."""
    return frame(cobid.TPDO1 + node, VALVE_TPDO.pack(status_word & 0xFFFF, spool_raw), timestamp_s)


def unpack_valve_tpdo(data: bytes) -> tuple[int, int] | None:
    """(status word, spool actual value) of the valve's TPDO 1; None when it is too short."""
    return VALVE_TPDO.unpack_from(data) if len(data) >= VALVE_TPDO.size else None


def encoder_tpdo(node: int, position_raw: int, timestamp_s: float = 0.0) -> can.Message:
    """The encoder's TPDO 1: position value."""
    return frame(cobid.TPDO1 + node, ENCODER_TPDO.pack(position_raw), timestamp_s)


def unpack_encoder_tpdo(data: bytes) -> int | None:
    """The position value (steps) of the encoder's TPDO 1; None when it is too short."""
    return int(ENCODER_TPDO.unpack_from(data)[0]) if len(data) >= ENCODER_TPDO.size else None


def unpack_emcy(data: bytes) -> tuple[int, int] | None:
    """(error code, error register) of an EMCY frame; None when it is too short."""
    if len(data) < 3:
        return None
    code, register = struct.unpack_from("<HB", data)
    return int(code), int(register)


def unpack_heartbeat(data: bytes) -> NmtState | None:
    """The NMT state a heartbeat shows (bit 7, the toggle of node guarding, masked); None for a
    payload that is no heartbeat."""
    if len(data) != 1:
        return None
    try:
        return NmtState(data[0] & 0x7F)
    except ValueError:
        return None
