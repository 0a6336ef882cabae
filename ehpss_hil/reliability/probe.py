"""A probe control law that says on the bus which sensor sample each cycle acted on.

Loaded into a real controller process with ``ehpss-hil controller --controller-factory
ehpss_hil.reliability.probe:probe_factory``: everything around it (receive, E2E, watchdog,
lifecycle, one VALVE_CMD per cycle) is the daemon's own code. A cycle with a fresh measurement
commands ``CURRENT_PER_M × position`` (A), a cycle without one 0 A, so a sender that encodes sample
number i as the position ``i × POSITION_STEP_M`` reads i back from each VALVE_CMD.
"""

from __future__ import annotations

from ..config import ControllerConfig
from ..control.base import Controller, Measurement, ValveCommand
from ..physics.params import Params

#: sample i is sent as position i × this (m): 10 LSB of SENSOR_POS Position
POSITION_STEP_M = 1e-6
#: the probe's gain (A/m): 2 µA per sample number, 10 LSB of VALVE_CMD CurrentSetpoint
CURRENT_PER_M = 2.0


def sample_of(current_a: float) -> int:
    """The sample number a probe command carries (0: the cycle had no fresh measurement)."""
    return round(current_a / (CURRENT_PER_M * POSITION_STEP_M))


class ProbeController(Controller):
    """Echoes the fresh position as a current; 0 A without fresh data."""

    mode = "nrc"

    def configure(self, params: Params, ts_s: float) -> None:
        """Nothing to build."""

    def reset(self) -> None:
        """Stateless."""

    def step(self, meas: Measurement) -> ValveCommand:
        """``CURRENT_PER_M × position`` when ``meas.fresh``, else 0 A (A)."""
        return ValveCommand(CURRENT_PER_M * meas.position_m if meas.fresh else 0.0, True)


def probe_factory(mode: str, params: Params, ts_s: float, cfg: ControllerConfig) -> ProbeController:
    """The daemon's ``--controller-factory`` hook (the arguments are not needed)."""
    return ProbeController()
