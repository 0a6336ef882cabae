"""``ehpss-hil identify``'s engine: run the experiment, fit, check, write the params file and
the report. The command (:mod:`ehpss_hil.commands.identify`) only parses its arguments."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ..errors import EhpssError
from ..physics.load import load_params
from ..physics.params import Params, PlantParams
from ..scenario import Scenario, load_scenario
from .excitation import Excitation
from .experiment import Record, run_experiment
from .fit import FitResult, fit
from .paramsfile import write_params
from .report import write_report

#: a key whose 95 % interval is wider than this (relative) is not identified: nothing is written
MAX_REL_CI95 = 0.25


class NotIdentifiedError(EhpssError):
    """The fit ran but did not pin a key down (its interval too wide, or not finite)."""

    exit_code = 1


@dataclass
class Identification:
    """An experiment's record, its fit, and the plant the scenario emulated (lockstep)."""

    record: Record
    result: FitResult
    truth: PlantParams | None


def identify_lockstep(scenario: Scenario, params: Params, exc: Excitation | None = None) -> Identification:
    """Run the experiment against ``scenario``'s emulated plant (its ``plant:`` section over
    ``params.plant``) around the PI of ``params`` and fit, starting from ``params.plant``."""
    rec = run_experiment(scenario, exc or Excitation(), params)
    res = fit(rec, params)
    check(res)
    return Identification(rec, res, scenario.plant.plant_params(params.plant))


def check(result: FitResult) -> None:
    """Raise :class:`NotIdentifiedError` when a key's interval exceeds :data:`MAX_REL_CI95`."""
    for e in result.keys:
        if not math.isfinite(e.rel_ci95) or e.rel_ci95 > MAX_REL_CI95:
            raise NotIdentifiedError(
                f"identification failed: {e.name} not pinned down (95 % interval ±{100 * e.rel_ci95:.3g} %, "
                f"limit ±{100 * MAX_REL_CI95:g} %); the plant is not the linear model structure here"
            )


def run_lockstep(
    scenario_path: str,
    out: Path,
    report_dir: Path | None,
    params_path: str = "",
    exc: Excitation | None = None,
) -> Identification:
    """The lockstep form of the command: identify, write ``out`` (and the report)."""
    scenario = load_scenario(scenario_path)
    params = load_params(params_path or None)
    ident = identify_lockstep(scenario, params, exc)
    write_params(out, ident.result, scenario_path)
    if report_dir is not None:
        write_report(report_dir, ident.record, ident.result, ident.truth, scenario_path)
    return ident


def run_on_bus(
    config: Path,
    out: Path,
    report_dir: Path | None,
    exc: Excitation | None = None,
    lockstep: bool = False,
    rt_priority: int | None = None,
    cpu: int | None = None,
) -> Identification:
    """The live-bus form: the experiment with the daemon's loop on controller config ``config``'s
    bus (:mod:`.live`; ``rt_priority``/``cpu`` override its ``rt`` section), the fit from the
    config's params, ``out`` (and the report) written."""
    from .live import run_live

    rec, params = run_live(config, exc or Excitation(), lockstep, rt_priority, cpu)
    res = fit(rec, params)
    check(res)
    write_params(out, res, str(config))
    ident = Identification(rec, res, None)
    if report_dir is not None:
        write_report(report_dir, rec, res, None, str(config))
    return ident
