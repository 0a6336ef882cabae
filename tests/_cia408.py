"""An emulated CiA 408 valve + CiA 406 encoder (firmware-sim's CANopen loop, realtime, in a
thread) and ``canopen``'s own master on one python-can bus, for the independent checks.

Nothing is timed: every wait has a generous limit only so that a broken run fails instead of
hanging on a loaded host.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import canopen

from ehpss_hil.canlog import CandumpLogger
from ehpss_hil.config import Cia408Config
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol.cia408.check import check_nodes
from ehpss_hil.protocol.cia408.eds import ENCODER_EDS, VALVE_EDS
from ehpss_hil.runtime.rawio import RawFrameIO
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.scenario import Scenario
from firmware_sim.canopen_process import CanopenEmulatorProcess, CanopenOptions, build_nodes

#: generous limit of every wait (s)
LIMIT_S = 30.0
SDO_TIMEOUT_S = 5.0


def wait_until(cond: Callable[[], bool], limit_s: float = LIMIT_S) -> bool:
    """Poll ``cond`` until it holds (False after ``limit_s``)."""
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


class Cia408Rig:
    """The emulator on ``bus_kwargs`` (a thread) and a ``canopen.Network`` master on its own bus."""

    def __init__(
        self,
        bus_kwargs: dict[str, Any],
        cfg: Cia408Config | None = None,
        scenario: Scenario | None = None,
        log_path: Path | None = None,
    ) -> None:
        self.cfg = cfg or Cia408Config()
        params = load_params()
        valve_od, encoder_od = check_nodes(self.cfg, "test")
        self.bus = can.Bus(**bus_kwargs)
        self.logger = CandumpLogger(log_path) if log_path is not None else None
        self.io = RawFrameIO(self.bus, self.logger)
        self.emu = PlantEmulation(params, scenario or Scenario(name="cia408", duration_s=3600.0))
        valve, encoder = build_nodes(self.cfg, valve_od, encoder_od, self.io, params.plant.spool_stroke_m)
        self.proc = CanopenEmulatorProcess(
            self.emu, self.io, valve, encoder, CanopenOptions(stats_capacity=10_000)
        )
        self.net = canopen.Network()
        self.net.connect(**bus_kwargs)
        self.valve = self.net.add_node(self.cfg.valve_node, str(VALVE_EDS))
        self.encoder = self.net.add_node(self.cfg.encoder_node, str(ENCODER_EDS))
        for n in (self.valve, self.encoder):
            n.sdo.RESPONSE_TIMEOUT = SDO_TIMEOUT_S
        self.stop = StopFlag()
        self._thread = threading.Thread(target=self.proc.run_realtime, args=(self.stop,), daemon=True)

    def start(self) -> Cia408Rig:
        """Start the emulator and wait for both boot-up messages."""
        self._thread.start()
        assert wait_until(
            lambda: self.valve.nmt.state == "PRE-OPERATIONAL" and self.encoder.nmt.state == "PRE-OPERATIONAL"
        )
        return self

    def close(self) -> None:
        self.stop.set()
        self._thread.join(LIMIT_S)
        self.net.disconnect()
        self.io.close()
        self.bus.shutdown()

    def __enter__(self) -> Cia408Rig:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def heartbeat_state(node: Any, state: str, limit_s: float = LIMIT_S) -> str:
    """The NMT state of ``node``'s heartbeats until one shows ``state`` (a heartbeat sent before
    the node handled an NMT command may still arrive after it); the last one seen at the limit."""
    end = time.monotonic() + limit_s
    seen = node.nmt.wait_for_heartbeat(limit_s)
    while seen != state and time.monotonic() < end:
        seen = node.nmt.wait_for_heartbeat(limit_s)
    return str(seen)


def emcy_codes(node: Any) -> list[int]:
    """EMCY codes the master has logged for ``node``."""
    return [e.code for e in node.emcy.log]
