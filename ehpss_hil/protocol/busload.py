"""Bus load of a protocol profile: bits per classic CAN frame (worst-case bit stuffing) times the
frames each process sends per second, over the bit rate.

A data frame with ``n`` data bytes has a stuffed part — SOF, arbitration, control, data and the
15-bit CRC: 34 + 8n bits with an 11-bit ID, 54 + 8n with a 29-bit ID (SRR, IDE and 18 more ID
bits) — in which the sender inserts a stuff bit after every 5 equal bits, at worst one per 4 bits
after the first: ⌊(s − 1)/4⌋; then 13 unstuffed bits (CRC delimiter, ACK slot and delimiter,
7-bit EOF, 3-bit intermission). An 8-byte frame: 135 bits standard, 160 extended (the bound of
R. I. Davis, A. Burns, R. J. Bril, J. J. Lukkien, *Controller Area Network (CAN) schedulability
analysis: refuted, revisited and revised*, Real-Time Systems 35, 2007).

The traffic of a deployment (no bench-only frames: PLANT_TRUTH, PLANT_FAULTS, FAULT_INJECT,
SETPOINT): per control period one SENSOR_POS, one SENSOR_AUX and one VALVE_CMD; CTRL_STATUS at
the status rate, followed by one CTRL_INDEX per model of the controller; CTRL_STATS; both
heartbeats.
"""

from __future__ import annotations

from dataclasses import dataclass

#: bits of a data frame outside bit stuffing: CRC delimiter 1, ACK 2, EOF 7, intermission 3
UNSTUFFED_BITS = 13
#: stuffed bits besides the data: SOF, ID, RTR, IDE, r0, DLC, CRC (11-bit ID)
STUFFED_OVERHEAD_STANDARD = 34
#: the same with a 29-bit ID (SRR, IDE, 18 more ID bits, r1)
STUFFED_OVERHEAD_EXTENDED = 54
#: the bus load a deployment may plan for: above it, arbitration delays the lower-priority
#: frames of a cycle by more than the period's slack and a retransmitted frame has no room
BUS_LOAD_LIMIT = 0.70
#: frames sent once per control period
PERIODIC_FRAMES = ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD")


def frame_bits(data_bytes: int, extended: bool) -> int:
    """Worst-case length (bits) of a classic CAN data frame with ``data_bytes`` (0..8) bytes."""
    if not 0 <= data_bytes <= 8:
        raise ValueError("classic CAN carries 0..8 data bytes")
    stuffed = (STUFFED_OVERHEAD_EXTENDED if extended else STUFFED_OVERHEAD_STANDARD) + 8 * data_bytes
    return stuffed + (stuffed - 1) // 4 + UNSTUFFED_BITS


@dataclass(frozen=True)
class FrameRate:
    """One frame on the bus: its name, data bytes, ID format and rate (frames/s)."""

    name: str
    data_bytes: int
    extended: bool
    rate_hz: float

    @property
    def bits_per_s(self) -> float:
        """Worst-case bits per second this frame takes."""
        return frame_bits(self.data_bytes, self.extended) * self.rate_hz


def load(frames: list[FrameRate], bitrate_bps: float) -> float:
    """Worst-case bus load (fraction of the bit rate) of ``frames``."""
    return sum(f.bits_per_s for f in frames) / bitrate_bps
