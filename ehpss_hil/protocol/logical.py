"""The controller's logical signals: what a protocol profile must deliver and accept.

The native DBC defines them (frame and signal names, SI units); a profile maps each onto its own
frames. The controller's cycle groups them in three logical frames: SENSOR_POS (position and
spool, the frame a cycle steps on), SENSOR_AUX (load pressure and coil-current echo, the second
of the sensor pair) and VALVE_CMD (current setpoint and enable).

Needed resolution: the coarsest LSB (SI) a profile may carry for each signal. Each is set where
the quantisation stops mattering for the control targets (docs/design.md §11: fault-free RMS
≤ 3 µm, modes compared within 2 µm), as measured with the lockstep simulator with every other
signal at the native LSB (figures: docs/hardware.md):

* position: the feedback itself; a 1 µm LSB adds at most 0.5 µm to any reading and changes the
  fault-free RMS by about a hundredth of a µm;
* spool: read by the k_LOE bank and the saturation judgement; 1 µm (1e-4 of the ±10 mm stroke)
  changes no metric measurably;
* load pressure: read by the flow-gain attribution (a slow regression); 0.1 bar;
* currents (setpoint and echo): the loop gain makes these the tightest: the PI's proportional
  path asks 4.4 µA per µm of error (K_f·k_p·k_a), and a 30 µA LSB (a 16-bit ±1 A field) already
  more than doubles the fault-free RMS; 10 µA keeps it within a tenth of a µm. The sample clock
  also takes an echo within ``WIRE_MATCH_A`` (30 µA) of a kept command as confirming it, which
  the two roundings of a 10 µA setpoint and a 10 µA echo (10 µA at most) leave room for.
"""

from __future__ import annotations

from dataclasses import dataclass

#: coarsest position LSB the controller accepts (m)
POSITION_RESOLUTION_M = 1e-6
#: coarsest spool-position LSB (m)
SPOOL_RESOLUTION_M = 1e-6
#: coarsest load-pressure LSB (Pa): 0.1 bar
LOAD_PRESSURE_RESOLUTION_PA = 1e4
#: coarsest LSB of the coil-current setpoint and of its echo (A)
CURRENT_RESOLUTION_A = 1e-5

#: a mapped field holds at least this many steps of its signal's needed resolution: a narrower
#: one (a factor of 1e-300, a range of [0, 0.001] mA) cannot carry the signal at all
MIN_FIELD_STEPS = 100

#: the logical frames, in the order the map's E2E section names them (``e2e.sensor_pos`` …)
LOGICAL_FRAMES = ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD")


@dataclass(frozen=True)
class LogicalSignal:
    """One logical signal: its map key, its native frame and signal, its quantity (the units a
    DBC may give it in) and the coarsest LSB it may have (SI; None: a 0/1 flag)."""

    key: str
    frame: str
    signal: str
    quantity: str
    resolution: float | None


LOGICAL_SIGNALS = (
    LogicalSignal("position", "SENSOR_POS", "Position", "length", POSITION_RESOLUTION_M),
    LogicalSignal("spool", "SENSOR_POS", "Spool", "length", SPOOL_RESOLUTION_M),
    LogicalSignal("load_pressure", "SENSOR_AUX", "LoadPressure", "pressure", LOAD_PRESSURE_RESOLUTION_PA),
    LogicalSignal("coil_current", "SENSOR_AUX", "CoilCurrent", "current", CURRENT_RESOLUTION_A),
    LogicalSignal("current_setpoint", "VALVE_CMD", "CurrentSetpoint", "current", CURRENT_RESOLUTION_A),
    LogicalSignal("enable", "VALVE_CMD", "Enable", "flag", None),
)

#: SI value of one DBC unit, per quantity (the unit strings a mapped signal may carry)
UNITS: dict[str, dict[str, float]] = {
    "length": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "bar": 1e5, "mbar": 1e2, "psi": 6894.757293168},
    "current": {"A": 1.0, "mA": 1e-3, "uA": 1e-6, "µA": 1e-6},
    "flag": {"": 1.0},
}
