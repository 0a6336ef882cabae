"""What a controller loop is configured with: its rates, fail-safe policy and own frames."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..config import SetpointPolicy, Watchdog

OWN_FRAMES = ("VALVE_CMD", "CTRL_STATUS", "CTRL_INDEX", "CTRL_STATS", "HEARTBEAT_CTRL")
#: the frames the CANopen master (``protocol: cia408``) sends besides
CIA408_OWN_FRAMES = ("SYNC", "CTRL_DEVICE", "NMT")


@dataclass(frozen=True)
class LoopOptions:
    """Rates (Hz) and fail-safe policy of the loop."""

    rate_hz: float = 1000.0
    status_rate_hz: float = 50.0
    heartbeat_rate_hz: float = 10.0
    stats_rate_hz: float = 10.0
    watchdog: Watchdog = field(default_factory=Watchdog)
    #: which SETPOINT frames may override x_d
    setpoint: SetpointPolicy = field(default_factory=SetpointPolicy)
    current_limit_a: float = 1.0
    lockstep_idle_s: float = 2.0
    #: a one-line counter summary in the log every this many seconds of cycles (0 = never)
    stats_interval_s: float = 10.0
    #: phase lock: age of the sensor frame at the controller's deadline (s); 0 = free grid
    #: (off by default: a small age also shrinks the stall tolerance of the watchdog, see
    #: docs/runtime.md)
    sensor_age_target_s: float = 0.0
    #: start the cycle as soon as a usable SENSOR_POS + SENSOR_AUX pair has arrived (waiting on
    #: the bus socket, never spinning), the deadline being the latest start; needs a bus with
    #: a file descriptor (udp_multicast, socketcan), else the plain grid is used
    wake_on_sensor: bool = False
    stats_capacity: int = 600_000
