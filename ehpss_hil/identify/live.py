"""The identification experiment on a live bus: the PI (nrc) wrapped so that it tracks the
excitation reference, checks the experiment's limits and records what it measures, run by the
daemon's own loop (:func:`ehpss_hil.daemon.run_daemon`, any protocol profile of the config).

The record runs on the sensor's sample clock, not on the loop's cycles: each sample goes to the
row its E2E counter says (:attr:`Measurement.samples` since the one before; 0, unknown, is one
per cycle), superseded samples (:meth:`ExcitationController.observe`) included. A realtime loop
on a free grid slips against the sensor: near a phase where frames arrive at the cycle's
deadline, cycles alternately find no pair and two; the sample clock keeps both samples. In
lockstep both clocks agree. A limit crossed: from that sample on the command is 0 A with Enable
0 (the valve's fail-safe) and, after the run, :class:`~.experiment.ExperimentAborted` names it.

In realtime the loop's watchdog stays armed: a host that stalls the loop (or the emulator) for
``watchdog.timeout_cycles`` periods trips it (SENSOR_TIMEOUT or LOOP_OVERRUN), the loop holds
fail-safe for the rest of the run and the record stops there. :func:`explain_trip` turns the
daemon's summary into the one line that says so and what the host needs (docs/identify.md).
"""

from __future__ import annotations

import json
import logging
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..control.base import Controller, Measurement, ValveCommand
from ..physics.params import Params
from .excitation import Excitation
from .experiment import ExperimentAborted, Record

log = logging.getLogger("ehpss_hil.identify")

#: the share of the experiment's sensor samples that must arrive for a fit
MIN_SAMPLE_FRACTION = 0.9


class ExcitationController(Controller):
    """``inner`` (the PI) on the excitation's reference, with limits and a record (SI)."""

    def __init__(self, inner: Controller, exc: Excitation, ts_s: float) -> None:
        self.inner, self.exc, self.ts_s = inner, exc, ts_s
        self.mode = inner.mode
        self.x_d = exc.reference(ts_s)
        self._rows = np.full((len(self.x_d), 4), np.nan)  # position, spool, pressure, echo
        self.k = 0  # the next cycle
        self._sample = -1  # the row of the last recorded sample
        self.reason = ""

    def configure(self, params: Params, ts_s: float) -> None:
        self.inner.configure(params, ts_s)

    def reset(self) -> None:
        self.inner.reset()

    def step(self, meas: Measurement) -> ValveCommand:
        k, n = self.k, len(self.x_d)
        self.k += 1
        if self.reason or k >= n:
            return ValveCommand(0.0, False)
        if meas.fresh:
            self._take(meas, k)
        meas.reference_m = float(self.x_d[k])
        cmd = self.inner.step(meas)
        self._check(cmd.current_a, self.exc.current_limit_a, "current |I|", k)
        return ValveCommand(0.0, False) if self.reason else cmd

    def observe(self, meas: Measurement) -> None:
        """A sample a newer one superseded within a cycle: recorded (and checked) too."""
        if not self.reason:
            self._take(meas, self._sample + 1)

    def _take(self, meas: Measurement, cycle: int) -> None:
        """Record ``meas`` on the sample clock (row: the last one + ``meas.samples``, or
        ``cycle`` when the counter is unknown) and check the measured limits."""
        row = self._sample + meas.samples if meas.samples > 0 and self._sample >= 0 else cycle
        self._sample = row
        if 0 <= row < len(self._rows):
            self._rows[row] = (meas.position_m, meas.spool_m, meas.load_pressure_pa, meas.coil_current_a)
        self._check(meas.position_m, self.exc.travel_limit_m, "travel |y_s|", row)
        self._check(meas.spool_m, self.exc.spool_limit_m, "spool |x_v|", row)

    def _check(self, value: float, limit: float, what: str, k: int) -> None:
        if not self.reason and not abs(value) <= limit:
            self.reason = (
                f"identification stopped in fail-safe at t = {k * self.ts_s:.3f} s: {what} = "
                f"{abs(value):.4g} exceeds its limit {limit:.4g} (SI units); lower --amplitude or "
                "raise the limit"
            )

    def samples_recorded(self) -> int:
        """How many cycles recorded a fresh sensor sample."""
        return int(np.isfinite(self._rows[:, 0]).sum())

    def last_sample_s(self) -> float:
        """The time of the last recorded sample (s from the start; -1 when none)."""
        fresh = np.flatnonzero(np.isfinite(self._rows[:, 0]))
        return float(fresh[-1]) * self.ts_s if fresh.size else -1.0

    def record(self) -> Record:
        """The measurements (raises :class:`ExperimentAborted` when a limit was crossed, or when
        too few samples arrived). A lost current echo is taken as the one before it."""
        if self.reason:
            raise ExperimentAborted(self.reason)
        rows = self._rows
        got = self.samples_recorded()
        if got < MIN_SAMPLE_FRACTION * len(rows):
            raise ExperimentAborted(
                f"identification incomplete: {got} of {len(rows)} sensor samples arrived (is the "
                "valve or the emulator on the bus?)"
            )
        echo = np.append(rows[1:, 3], np.nan)
        last = 0.0
        for i, v in enumerate(echo):
            echo[i] = last = v if math.isfinite(v) else last
        n_period = round(self.exc.period_s / self.ts_s)
        return Record(self.ts_s, self.x_d, rows[:, 0], rows[:, 1], rows[:, 2], echo, n_period)


def run_live(
    config: Path,
    exc: Excitation,
    lockstep: bool = False,
    rt_priority: int | None = None,
    cpu: int | None = None,
) -> tuple[Record, Params]:
    """Run the experiment with the daemon's loop on the bus of controller config ``config``
    (its params, protocol, rate; ``rt_priority``/``cpu`` override its ``rt`` section); returns
    the record and the config's params. A record cut short by a watchdog trip raises
    :class:`ExperimentAborted` with :func:`explain_trip`'s line."""
    from ..config import ControllerConfig
    from ..daemon import DaemonArgs, resolve_config, run_daemon
    from ..physics.load import load_params

    cfg = resolve_config(DaemonArgs(config=config, rt_priority=rt_priority, cpu=cpu))
    if not lockstep and cfg.rt.priority == 0:
        log.warning(
            "realtime without SCHED_FIFO (rt.priority 0): on a loaded host a stall of %d periods "
            "trips the watchdog and ends the experiment; see --rt-priority/--cpu or --lockstep",
            cfg.watchdog.timeout_cycles,
        )
    params = load_params(cfg.params or None)
    made: list[ExcitationController] = []

    def factory(mode: str, prm: Params, ts_s: float, c: ControllerConfig) -> Controller:
        from ..control.registry import make_controller

        made.append(ExcitationController(make_controller("nrc", prm, ts_s, c.tuning), exc, ts_s))
        return made[0]

    duration = exc.period_s * exc.periods
    with tempfile.TemporaryDirectory(prefix="ehpss-identify-") as tmp:
        summary_path = Path(tmp) / "summary.json"
        args = DaemonArgs(
            config=config,
            mode="nrc",
            duration_s=duration,
            lockstep=lockstep,
            factory=factory,
            summary_json=summary_path,
            rt_priority=rt_priority,
            cpu=cpu,
        )
        run_daemon(args)
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    ctrl = made[0]
    if not ctrl.reason and ctrl.samples_recorded() < MIN_SAMPLE_FRACTION * len(ctrl.x_d):
        why = explain_trip(summary, ctrl, cfg.rate_hz, lockstep)
        if why:
            raise ExperimentAborted(why)
    return ctrl.record(), params


def explain_trip(summary: dict[str, Any], ctrl: ExcitationController, rate_hz: float, lockstep: bool) -> str:
    """The one line for a run whose record stopped because the loop's watchdog tripped ('' when
    it did not): the reason, when the samples stopped, the loop's lateness and overruns, and what
    the host needs. ``summary`` is the daemon's exit summary (:func:`loop_summary`)."""
    trips = summary.get("watchdog_trips_by_reason") or {}
    if not trips:
        return ""
    stats = summary.get("stats") or {}
    late_p99_s = float((stats.get("lateness_s") or {}).get("p99", float("nan")))
    n = len(ctrl.x_d)
    line = (
        f"identification stopped in fail-safe: the loop's watchdog tripped "
        f"({', '.join(f'{k} x{v}' for k, v in trips.items())}); {ctrl.samples_recorded()} of {n} "
        f"sensor samples recorded, the last at t = {ctrl.last_sample_s():.3f} s"
    )
    if lockstep:
        return line + " (lockstep: did the emulator stop early?)"
    return line + (
        f"; loop lateness p99 {late_p99_s * 1e6:.0f} µs, {stats.get('overruns', 0)} overruns at "
        f"{rate_hz:g} Hz: this host did not keep the loop's deadlines. Give the loop and the "
        "emulator SCHED_FIFO on CPUs of their own (--rt-priority/--cpu here, rt.priority/rt.cpu "
        "in the config; firmware-sim --rt-priority/--cpu), or run --lockstep (docs/identify.md)"
    )
