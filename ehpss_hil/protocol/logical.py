"""The controller's logical signals: what a protocol profile must deliver and accept.

The native DBC defines them (frame and signal names, SI units); a profile maps each onto its own
frames. The controller's cycle groups them in three logical frames: SENSOR_POS (position and
spool, the frame a cycle steps on), SENSOR_AUX (load pressure and coil-current echo, the second
of the sensor pair) and VALVE_CMD (current setpoint and enable).

Needed resolution: the coarsest LSB (SI) a profile may carry for each signal, as measured by
``ehpss-hil bench resolution`` (ehpss_hil/bench/resolution.py; table and figures in
docs/hardware.md §1): each signal's LSB swept with every other signal at the native LSB, over
the paper's cases 1–3 and the fault-free run (three seeds each). The *derived* limit is the
coarsest LSB below which every swept one keeps mmac from harm (against nrc), compensating
(within 5 µm of the oracle) and within 1 µm of its native fault-free RMS; the limit here is one
grid step finer (the response is not monotonic in the LSB and degrades before it fails: an echo
of 4 µA passes, with a 74 µm peak in case 3), and the DBC with every signal at its limit at once
passes the same test. Re-run the bench after a change to the control law; it
fails when a limit here is coarser than the one it derives.

* position: the feedback itself;
* spool: the k_LOE bank and the saturation judgement;
* load pressure: the flow-gain (k_Q) attribution;
* coil-current echo: the tightest: the valve models run on the echo (16.5 µm of steady spool
  per µA), so an echo rounded by a few µA shows the k_LOE bank a spool error far above the LVDT's
  noise, and mmac stops compensating case 2 and 3 at 4.5 µA;
* current set-point: what the valve applies; it costs the fault-free RMS (the PI asks 4.4 µA per
  µm of error) before anything else. With the echo's limit it leaves the sample clock its
  ``WIRE_MATCH_A`` (30 µA) of room for the two roundings.
"""

from __future__ import annotations

from dataclasses import dataclass

#: coarsest position LSB the controller accepts (m); origin: bench resolution (derived 5 µm, the
#: grid's coarsest)
POSITION_RESOLUTION_M = 3e-6
#: coarsest spool-position LSB (m); origin: bench resolution (derived 20 µm, the grid's coarsest)
SPOOL_RESOLUTION_M = 1e-5
#: coarsest load-pressure LSB (Pa): 0.2 bar; origin: bench resolution (derived 0.3 bar)
LOAD_PRESSURE_RESOLUTION_PA = 2e4
#: coarsest LSB of the coil-current echo (A); origin: bench resolution (derived 4 µA)
COIL_CURRENT_RESOLUTION_A = 3e-6
#: coarsest LSB of the coil-current set-point (A); origin: bench resolution (derived 30 µA)
CURRENT_RESOLUTION_A = 2e-5

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
    LogicalSignal("coil_current", "SENSOR_AUX", "CoilCurrent", "current", COIL_CURRENT_RESOLUTION_A),
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
