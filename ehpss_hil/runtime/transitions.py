"""The daemon loop's lifecycle transitions, decided once per cycle from that cycle's evidence
(docs/design.md §8): CONFIGURED → ACTIVE on the first usable sensor data (and a ready CANopen
master), ACTIVE → FAULT on the watchdog, a second transmitter, the bus or a device, FAULT →
ACTIVE once the watchdog has seen fresh data long enough and nothing else holds the fault; in
FAULT the more specific diagnosis replaces the reason (a second transmitter first, then the
device's own). :class:`~.controller_loop.ControllerLoop` owns one and calls it each cycle."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from ..driver import ControllerDriver
from ..protocol.failsafe import FailsafeReason
from .bushealth import BusHealth
from .foreign import CollisionGuard
from .lifecycle import Lifecycle, State
from .watchdog import SensorWatchdog

if TYPE_CHECKING:
    from ..protocol.cia408.master import CyclicMaster

log = logging.getLogger("ehpss_hil.controller")

#: who put the loop into FAULT, for the log (anything else: the CANopen master's device checks)
_SOURCE = {
    None: "watchdog",
    FailsafeReason.ID_COLLISION: "second transmitter",
    FailsafeReason.BUS_ERROR: "bus",
}


class Transitions:
    """Each cycle's transition of ``life`` from the evidence of the watchdog ``wd``, the
    second-transmitter ``guard``, the bus ``health`` and the CANopen ``master`` (None: none);
    ``driver`` restarts the controller on leaving FAULT; ``failsafe``: the fail-safe command's
    name, for the log."""

    def __init__(
        self,
        life: Lifecycle,
        wd: SensorWatchdog,
        guard: CollisionGuard,
        health: BusHealth,
        driver: ControllerDriver,
        master: CyclicMaster | None,
        failsafe: str,
    ) -> None:
        self.life, self.wd, self.guard, self.health = life, wd, guard, health
        self.driver, self.master, self.failsafe = driver, master, failsafe

    def update(
        self,
        cycles: int,
        mode: str,
        sensor_fresh: bool,
        e2e_bad: int,
        implausible: int,
        late: bool,
        stale: int,
        stale_after_s: float,
    ) -> None:
        """Cycle ``cycles``: a usable SENSOR_POS arrived (``sensor_fresh``), ``e2e_bad`` sensor
        frames failed E2E, ``implausible`` were out of range, the cycle started ``late``,
        ``stale`` frames older than ``stale_after_s`` (s) were dropped; ``mode``: the
        controller's, for the log."""
        st = self.life.state
        collided = self.guard.update(cycles)
        master = self.master
        device = master.update(cycles) if master is not None else None
        if collided and master is not None:  # the valve shut out (first cause only)
            master.second_transmitter(self.guard.last_cause)
        if self.health.update(cycles):  # nothing reaches the valve: before any device
            device = FailsafeReason.BUS_ERROR
        if st is State.CONFIGURED:
            if sensor_fresh and (master is None or master.ready):
                self.wd.reset()
                self.life.to(State.ACTIVE)
                log.info("first sensor data: ACTIVE (mode %s)", mode)
                if collided:
                    self.enter_fault(cycles, FailsafeReason.ID_COLLISION)
            return
        if stale:
            log.warning(
                "cycle %d: %d stale sensor frame(s) (received > %.3g ms ago) dropped",
                cycles,
                stale,
                stale_after_s * 1e3,
            )
        fresh = sensor_fresh and (master is None or master.status_fresh)
        tripped = self.wd.update(fresh, e2e_bad, implausible, late)
        if st is State.ACTIVE:
            if device is not None:
                self.enter_fault(cycles, device)
            elif tripped or collided:
                self.enter_fault(cycles, None if tripped else FailsafeReason.ID_COLLISION)
        elif st is State.FAULT:
            self._in_fault(cycles, collided, device, tripped)

    def _in_fault(self, cycles: int, collided: bool, device: FailsafeReason | None, tripped: bool) -> None:
        """FAULT: a more specific reason, or ACTIVE again."""
        life = self.life
        if collided:  # the more specific diagnosis
            if life.reason is not FailsafeReason.ID_COLLISION:
                log.error(
                    "cycle %d: second transmitter: FAULT reason %s -> ID_COLLISION",
                    cycles,
                    life.reason.name,
                )
            life.reason = FailsafeReason.ID_COLLISION
        elif device is not None and life.reason is not device:
            # the device's own diagnosis (EMCY, leaving ACTIVE, a lost heartbeat) is more specific
            # than a starved loop's or a silent sensor's: it is what has to be cleared first
            if life.reason is not FailsafeReason.ID_COLLISION:
                log.error("cycle %d: FAULT reason %s -> %s", cycles, life.reason.name, device.name)
                life.reason = device
        elif not tripped and device is None:
            self.driver.restart()
            life.to(State.ACTIVE)
            log.warning(
                "cycle %d: sensor data fresh for %d cycles: ACTIVE again", cycles, self.wd.fresh_cycles
            )

    def enter_fault(self, cycles: int, reason: FailsafeReason | None = None) -> None:
        """ACTIVE → FAULT in cycle ``cycles`` for ``reason`` (None: the watchdog's)."""
        why = self.wd.reason if reason is None else reason
        self.life.to(State.FAULT, why)
        log.error(
            "cycle %d: %s: %s -> FAULT, fail-safe %s",
            cycles,
            _SOURCE.get(reason, "device"),
            why.name,
            self.failsafe,
        )
