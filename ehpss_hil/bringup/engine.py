"""The bring-up run: bit rate, the daemon's start-up, the sequence, the findings.

The daemon (:func:`ehpss_hil.daemon.run_daemon`) runs the :class:`~.sequence.BringupController`
as its controller on the config's bus and protocol profile, so a CiA 408 valve is started by
the same master (identity against the config, configuration by SDO, NMT) and a vendor valve is
driven through its own DBC; a failure there is that start-up's own one line (exit 2 or 3).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from ..config import ControllerConfig
from ..control.base import Controller
from ..errors import BringupRefused
from ..physics.load import load_params
from ..physics.params import Params
from .judge import Finding, judge
from .sequence import BringupController, BringupPlan

log = logging.getLogger("ehpss_hil.bringup")
#: the daemon runs this much longer than the sequence (s): its last cycles send 0 A, Enable 0
TAIL_S = 0.05


@dataclass(frozen=True)
class BringupResult:
    """The bit-rate note, every finding, and the test current (A)."""

    bitrate: str
    findings: tuple[Finding, ...]
    current_a: float

    @property
    def ok(self) -> bool:
        """Every finding passed."""
        return all(f.ok for f in self.findings)

    def refusal(self) -> str:
        """The first failed finding's line (empty when all passed)."""
        bad = next((f for f in self.findings if not f.ok), None)
        return f"bring-up refused: {bad.name}: {bad.text}" if bad else ""


def run_bringup(config: Path, plan: BringupPlan, lockstep: bool = False) -> BringupResult:
    """The bring-up on the bus of controller config ``config`` (module docstring)."""
    from ..bus.bitrate import check_bitrate
    from ..daemon import DaemonArgs, resolve_config, run_daemon

    cfg = resolve_config(DaemonArgs(config=config))
    note = check_bitrate(cfg.bus, str(config))  # exit 2 when it differs
    params = load_params(cfg.params or None)
    current = plan.current_share * params.plant.stroke_current_a
    made: list[BringupController] = []

    def factory(mode: str, prm: Params, ts_s: float, c: ControllerConfig) -> Controller:
        made.append(BringupController(plan, current, ts_s))
        return made[0]

    run_daemon(
        DaemonArgs(
            config=config,
            mode="nrc",
            duration_s=plan.duration_s() + TAIL_S,
            lockstep=lockstep,
            factory=factory,
        )
    )
    return BringupResult(note, tuple(judge(made[0], params.plant)), current)


def require_ok(result: BringupResult) -> None:
    """Raise :class:`BringupRefused` with the first failed finding's line."""
    if not result.ok:
        raise BringupRefused(result.refusal())
