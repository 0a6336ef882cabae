"""Driving a :class:`~.controller_loop.ControllerLoop` (this module sits above it): the
realtime deadline grid, lockstep (one cycle per received sensor pair), and the counters it
reports at exit."""

from __future__ import annotations

import logging
import time

from ..codec import Verdict
from .controller_loop import ControllerLoop
from .deadline import DeadlineTimer, socket_wake
from .phaselock import PhaseLock
from .signals import StopFlag
from .stats import peak_rss_bytes

log = logging.getLogger("ehpss_hil.controller")

#: lockstep: the longest single wait for a frame (s); a stop request (SIGTERM/SIGINT) ends the
#: loop within it, however long the idle limit is
LOCKSTEP_POLL_S = 0.1


def run_realtime(loop: ControllerLoop, stop: StopFlag, n_cycles: int | None = None) -> None:
    """Cycles on the deadline grid until ``stop`` or ``n_cycles``; with ``wake_on_sensor`` a
    cycle starts as soon as its sensor pair is in, the deadline being the latest start; with a
    sensor-age target the grid is phase-locked to the sensor frames."""
    ts_s = loop.ts_s
    timer = DeadlineTimer(ts_s, name="controller")
    target = min(loop.opts.sensor_age_target_s, 0.5 * ts_s)
    lock = PhaseLock(ts_s, target) if target > 0.0 else None
    wake = socket_wake(loop.io.bus, loop.drain_for_wake) if loop.opts.wake_on_sensor else None
    drain_backlog(loop)
    timer.start()
    perf = time.perf_counter
    while not stop and (n_cycles is None or loop.cycles < n_cycles):
        lateness = timer.wait(wake)
        t0 = perf()
        woken = lateness < 0.0
        if woken:  # by the sensor pair: lateness from its arrival
            loop.woken_by_sensor += 1
            lateness = loop.wake_lateness_s
        # woken: the bus was drained to its last frame microseconds ago (and no period was
        # skipped); another read would only learn that nothing is pending
        rx_wall = loop.poll_cycle(timer.last_skipped, drain=not woken, late=timer.last_late)
        if lock is not None and rx_wall is not None:
            arrival = rx_wall - (time.time() - time.monotonic())
            timer.shift(lock.correction(timer.next_deadline_s - ts_s, arrival))
        dt = perf() - t0
        loop.stats.compute.add(dt)
        loop.stats.lateness.add(lateness)
        loop.periodic.record_compute(dt)
        loop.overruns = timer.overruns
    loop.stats.overruns = timer.overruns
    loop.stats.skipped = timer.skipped


def drain_backlog(loop: ControllerLoop, batch: int = 1000) -> None:
    """The frames queued since the bus opened (the emulator sends ~3000/s): classified before
    the grid starts (the stale ones dropped), not in the first cycle, which they would make
    several periods late — a LOOP_OVERRUN right at the start."""
    while loop.drain(batch) == batch:
        pass


def run_lockstep(loop: ControllerLoop, stop: StopFlag, n_cycles: int | None = None) -> None:
    """One cycle per received sensor pair, until ``stop`` (seen within ``LOCKSTEP_POLL_S``),
    ``n_cycles`` or the bus is idle for ``lockstep_idle_s`` after the first frame (before it,
    the loop waits for the peer however long it takes to start).

    A cycle follows each SENSOR_AUX after a SENSOR_POS that was not a REPEATED copy (a
    duplicate must not step the law or answer twice; a corrupted or out-of-sequence one is
    still answered, as a cycle without data, so that the emulator's period completes)."""
    perf = time.perf_counter
    pending = False
    loop.lockstep = True
    idle_s = loop.opts.lockstep_idle_s
    last = 0.0  # when the last frame arrived (perf_counter s; 0: none yet)
    while not stop and (n_cycles is None or loop.cycles < n_cycles):
        msg = loop.io.recv(LOCKSTEP_POLL_S)
        if msg is None:
            if last and perf() - last >= idle_s:
                log.info("lockstep: bus idle for %.1f s; ending", idle_s)
                return
            continue
        t0 = last = perf()
        verdict = loop.on_frame(msg)
        if msg.arbitration_id == loop.id_pos:
            pending = verdict is not Verdict.REPEATED
        if msg.arbitration_id == loop.id_aux and pending:
            pending = False
            loop.cycle()
            loop.stats.compute.add(perf() - t0)


def _fallbacks(loop: ControllerLoop) -> int:
    """Entries of the controller's do-no-harm monitor into nominal compensation."""
    count = getattr(loop.controller, "fallback_count", None)
    return int(count()) if callable(count) else 0


def loop_summary(loop: ControllerLoop) -> dict[str, object]:
    """Counters and loop statistics (JSON-able): the daemon's exit summary."""
    io = loop.io
    return {
        "cycles": loop.cycles,
        "skipped_periods": loop.skipped_periods,
        "stale_frames": loop.stale_frames,
        "woken_by_sensor": loop.woken_by_sensor,
        "state": loop.life.state.name,
        "failsafe_reason": loop.life.reason.name,
        "watchdog_trips": loop.wd.trips,
        "watchdog_trips_by_reason": dict(loop.wd.trips_by_reason),
        "watchdog_trip_at_end": loop.wd.silent_since_trip,
        "failsafe_cycles": loop.failsafe_cycles,
        "saturations": loop.saturations,
        "nominal_fallbacks": _fallbacks(loop),
        "frames_sent": dict(io.sent),
        "tx_errors": io.tx_errors,
        "frames_received": io.received,
        "id_collisions": dict(io.collisions.by_name),
        "second_transmitter": loop.guard.summary(),
        "bus_health": io.health.summary(),
        "setpoints": {"accepted": loop.setpoints.accepted, "rejected": loop.setpoints.rejected},
        "received_by_verdict": {v.name: n for v, n in loop.codec.counts.items()},
        "stats": loop.stats.summary(),
        "max_rss_bytes": peak_rss_bytes(),
        **({"cia408": loop.master.summary()} if loop.master is not None else {}),
    }
