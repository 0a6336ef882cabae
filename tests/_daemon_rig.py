"""The daemon loop's in-process rig: the loop (``ControllerLoop``) with a minimal PI over a
python-can ``virtual`` channel and a test peer playing the emulator (cycles are counted, nothing
is timed). A minimal PI keeps the loop tests independent of the control law."""

from __future__ import annotations

import time
from typing import Any

import can
from _virtual import VirtualPair

from ehpss_hil.codec import FrameCodec
from ehpss_hil.config import Watchdog
from ehpss_hil.control.base import Controller, ControllerStatus, Measurement, ValveCommand
from ehpss_hil.physics.params import Params
from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.lifecycle import State
from ehpss_hil.scenario import Reference


class MiniPI(Controller):
    """A tiny PI on the position error (A per m), enough to exercise the loop."""

    mode = "nrc"

    def __init__(self, kp: float = 0.05, ki: float = 0.5, ts_s: float = 1e-3) -> None:
        self.kp, self.ki, self.ts_s = kp, ki, ts_s
        self.z = 0.0
        self.steps = 0

    def configure(self, params: Params, ts_s: float) -> None:
        self.ts_s = ts_s

    def reset(self) -> None:
        self.z = 0.0

    def step(self, meas: Measurement) -> ValveCommand:
        e = meas.reference_m - meas.position_m
        self.z += self.ts_s * e
        self.steps += 1
        return ValveCommand(current_a=self.kp * e + self.ki * self.z, enable=True)

    def status(self) -> ControllerStatus:
        return ControllerStatus(mode=self.mode, index={0: 0.5}, theta={0: 1.0})


class Rig(VirtualPair):
    """Controller loop + a test peer playing the emulator on one virtual channel."""

    def __init__(self, name: str, wd: Watchdog | None = None) -> None:
        super().__init__(name)
        self.tx = FrameCodec()
        self.ctrl = MiniPI()
        self.loop = ControllerLoop(
            self.ctrl,
            FrameIO(self.bus, FrameCodec(), OWN_FRAMES),
            Reference(kind="step", amplitude_m=1e-3),
            LoopOptions(watchdog=wd or Watchdog()),
        )
        #: a second peer that keeps the timestamps it is given: frames received "long ago"
        self.old_peer = can.Bus(interface="virtual", channel=name, preserve_timestamps=True)

    def old_sensors(self, position_m: float, age_s: float) -> None:
        """A sensor pair whose receive timestamps lie ``age_s`` (s) in the past."""
        t = time.time() - age_s
        self.old_peer.send(
            self.tx.encode("SENSOR_POS", {"Position": position_m, "Spool": 0.0}, timestamp_s=t)
        )
        self.old_peer.send(self.tx.encode("SENSOR_AUX", {"CoilCurrent": 1e-5}, timestamp_s=t))

    def close(self) -> None:
        self.old_peer.shutdown()
        super().close()

    def sensors(self, position_m: float = 0.0) -> can.Message:
        pos = self.tx.encode("SENSOR_POS", {"Position": position_m, "Spool": 0.0})
        self.peer.send(pos)
        self.peer.send(self.tx.encode("SENSOR_AUX", {"CoilCurrent": 1e-5}))
        return pos

    def cycle(self) -> dict[str, dict[str, Any]]:
        """One loop cycle; returns the newest decoded frame of each name the loop sent."""
        self.loop.poll_cycle()
        return self.newest()

    def cycle_with(self, position_m: float) -> dict[str, Any]:
        """Sensor frames, then one cycle; returns its VALVE_CMD."""
        self.sensors(position_m)
        return self.cycle()["VALVE_CMD"]


def activate(rig: Rig, n: int = 5) -> None:
    for _ in range(n):
        rig.sensors()
        rig.cycle()
    assert rig.loop.life.state is State.ACTIVE
