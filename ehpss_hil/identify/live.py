"""The identification experiment on a live bus: the PI (nrc) wrapped so that it tracks the
excitation reference, checks the experiment's limits and records what it measures, run by the
daemon's own loop (:func:`ehpss_hil.daemon.run_daemon`, any protocol profile of the config).

One controller cycle is taken as one sensor sample (the loop phase-locks to the sensor; in
lockstep it is exact). A limit crossed: from that cycle on the command is 0 A with Enable 0 (the
valve's fail-safe) and, after the run, :class:`~.experiment.ExperimentAborted` names the limit.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..control.base import Controller, Measurement, ValveCommand
from ..physics.params import Params
from .excitation import Excitation
from .experiment import ExperimentAborted, Record


class ExcitationController(Controller):
    """``inner`` (the PI) on the excitation's reference, with limits and a record (SI)."""

    def __init__(self, inner: Controller, exc: Excitation, ts_s: float) -> None:
        self.inner, self.exc, self.ts_s = inner, exc, ts_s
        self.mode = inner.mode
        self.x_d = exc.reference(ts_s)
        self._rows = np.full((len(self.x_d), 4), np.nan)  # position, spool, pressure, echo
        self.k = 0
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
            self._rows[k] = (meas.position_m, meas.spool_m, meas.load_pressure_pa, meas.coil_current_a)
            self._check(meas.position_m, self.exc.travel_limit_m, "travel |y_s|", k)
            self._check(meas.spool_m, self.exc.spool_limit_m, "spool |x_v|", k)
        meas.reference_m = float(self.x_d[k])
        cmd = self.inner.step(meas)
        self._check(cmd.current_a, self.exc.current_limit_a, "current |I|", k)
        return ValveCommand(0.0, False) if self.reason else cmd

    def _check(self, value: float, limit: float, what: str, k: int) -> None:
        if not self.reason and not abs(value) <= limit:
            self.reason = (
                f"identification stopped in fail-safe at t = {k * self.ts_s:.3f} s: {what} = "
                f"{abs(value):.4g} exceeds its limit {limit:.4g} (SI units); lower --amplitude or "
                "raise the limit"
            )

    def record(self) -> Record:
        """The measurements (raises :class:`ExperimentAborted` when a limit was crossed, or when
        too few samples arrived). A lost current echo is taken as the one before it."""
        if self.reason:
            raise ExperimentAborted(self.reason)
        rows = self._rows
        got = int(np.isfinite(rows[:, 0]).sum())
        if got < 0.9 * len(rows):
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


def run_live(config: Path, exc: Excitation, lockstep: bool = False) -> tuple[Record, Params]:
    """Run the experiment with the daemon's loop on the bus of controller config ``config``
    (its params, protocol, rate); returns the record and the config's params."""
    from ..config import ControllerConfig
    from ..daemon import DaemonArgs, resolve_config, run_daemon
    from ..physics.load import load_params

    cfg = resolve_config(DaemonArgs(config=config))
    params = load_params(cfg.params or None)
    made: list[ExcitationController] = []

    def factory(mode: str, prm: Params, ts_s: float, c: ControllerConfig) -> Controller:
        from ..control.registry import make_controller

        made.append(ExcitationController(make_controller("nrc", prm, ts_s, c.tuning), exc, ts_s))
        return made[0]

    duration = exc.period_s * exc.periods
    run_daemon(DaemonArgs(config=config, mode="nrc", duration_s=duration, lockstep=lockstep, factory=factory))
    return made[0].record(), params
