"""The bring-up's bounded open-loop sequence, as a controller the daemon's loop runs.

Phases, each a whole number of sensor samples: ``rest`` (Enable 1, 0 A: the spool's null and
the sensors' zero and noise), ``plus`` (+I), ``minus`` (−I: brings the piston back where it
started), ``settle`` (0 A). I is a small share of the current that moves the spool to its
stroke (:attr:`BringupPlan.current_share`); the piston travels about K_c · K_sv · I · T in each
step phase. Limits, checked every sample: the piston more than :attr:`BringupPlan.travel_limit_m`
from where it rested, or the spool beyond :attr:`BringupPlan.spool_limit_m` — then 0 A with
Enable 0 (the valve's fail-safe) for the rest of the run, and the reason is kept.

The daemon (:func:`ehpss_hil.daemon.run_daemon`) runs it on any protocol profile, so the CiA 408
start-up (identity, configuration) and the bit-rate check come first, as for the controller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..control.base import Controller, Measurement, ValveCommand
from ..physics.params import Params
from ..schema import rng

#: the phases, in order
PHASES = ("rest", "plus", "minus", "settle")


@dataclass(frozen=True)
class BringupPlan:
    """The sequence's sizes (s, share of the stroke current) and limits (m)."""

    #: each phase's length (s): rest, plus, minus, settle
    rest_s: float = field(default=0.3, metadata=rng(0.05, 10.0))
    step_s: float = field(default=0.2, metadata=rng(0.02, 5.0))
    settle_s: float = field(default=0.1, metadata=rng(0.0, 10.0))
    #: the test current as a share of the coil current that moves the spool to its stroke
    current_share: float = field(default=0.1, metadata=rng(0.0, 0.5, lo_open=True))
    #: the piston may move at most this far from where it rested (m)
    travel_limit_m: float = field(default=2e-3, metadata=rng(0.0, 0.1, lo_open=True))
    #: the spool may read at most this far from the centre (m)
    spool_limit_m: float = field(default=5e-3, metadata=rng(0.0, 0.1, lo_open=True))

    def phase_samples(self, ts_s: float) -> tuple[int, int, int, int]:
        """Samples of each phase at sample time ``ts_s`` (s)."""
        return (
            max(1, round(self.rest_s / ts_s)),
            max(1, round(self.step_s / ts_s)),
            max(1, round(self.step_s / ts_s)),
            round(self.settle_s / ts_s),
        )

    def duration_s(self) -> float:
        """The whole sequence (s)."""
        return self.rest_s + 2 * self.step_s + self.settle_s


class BringupController(Controller):
    """Runs a :class:`BringupPlan` at ``current_a`` (A) and records every sample (SI)."""

    mode = "bringup"

    def __init__(self, plan: BringupPlan, current_a: float, ts_s: float) -> None:
        self.plan, self.current_a, self.ts_s = plan, current_a, ts_s
        n = plan.phase_samples(ts_s)
        self.bounds = tuple(int(x) for x in np.cumsum(n))  # end sample of each phase
        #: per sample: position, spool, echo (NaN: no fresh data); and the command sent
        self.rows = np.full((self.bounds[-1], 3), np.nan)
        self.commands = np.zeros(self.bounds[-1])
        self.k = 0
        self.reason = ""
        self._rest_position = math.nan

    def configure(self, params: Params, ts_s: float) -> None:
        self.ts_s = ts_s

    def reset(self) -> None:
        self.k, self.reason = 0, ""
        self.rows[:] = np.nan

    def phase(self, k: int) -> str:
        """The phase sample ``k`` belongs to ("" after the sequence)."""
        for name, end in zip(PHASES, self.bounds, strict=True):
            if k < end:
                return name
        return ""

    def step(self, meas: Measurement) -> ValveCommand:
        k = self.k
        self.k += 1
        if k >= len(self.rows):
            return ValveCommand(0.0, False)
        if meas.fresh:
            self.rows[k] = (meas.position_m, meas.spool_m, meas.coil_current_a)
            self._check(meas, k)
        if self.reason:
            return ValveCommand(0.0, False)
        phase = self.phase(k)
        current = {"plus": self.current_a, "minus": -self.current_a}.get(phase, 0.0)
        self.commands[k] = current
        return ValveCommand(current, True)

    def _check(self, meas: Measurement, k: int) -> None:
        if self.reason:
            return
        if k < self.bounds[0]:
            self._rest_position = meas.position_m
        moved = abs(meas.position_m - self._rest_position) if math.isfinite(self._rest_position) else 0.0
        t = k * self.ts_s
        if moved > self.plan.travel_limit_m:
            self.reason = (
                f"bring-up stopped in fail-safe at t = {t:.3f} s: the piston moved {moved * 1e3:.3g} mm "
                f"from rest, beyond the travel limit {self.plan.travel_limit_m * 1e3:g} mm"
            )
        elif abs(meas.spool_m) > self.plan.spool_limit_m:
            self.reason = (
                f"bring-up stopped in fail-safe at t = {t:.3f} s: the spool reads "
                f"{meas.spool_m * 1e3:.3g} mm, beyond the spool limit ±{self.plan.spool_limit_m * 1e3:g} mm"
            )
