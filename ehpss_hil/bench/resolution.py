"""``ehpss-hil bench resolution``: how coarse a field may be before mmac stops doing its job.

Each logical signal's LSB is swept (every other signal at the native LSB) by running the
lockstep simulator on a copy of the native DBC with that signal's factor changed
(:func:`ehpss_hil.sim.rescale.rescaled_dbc`; the same quantization a vendor DBC applies
through ``dbc-map``), over the paper's cases 1–3 and the fault-free run, for each seed, with
nrc, mmac and the oracle. A swept LSB is *fine* when, in every run:

* no harm: mmac RMS ≤ NO_HARM_RATIO · nrc RMS + NO_HARM_RMS_M and mmac's worst error ≤ nrc's
  + NO_HARM_PEAK_M (report/metrics.py :func:`does_harm`);
* compensated (cases 1–3): mmac RMS ≤ oracle RMS + COMPENSATED_RMS_M at the same LSB;
* cheap (fault-free): mmac RMS ≤ its RMS with every signal at the native LSB + QUALITY_RMS_M.

The *derived limit* of a signal is the largest swept LSB below which every swept LSB is fine
(the response is not monotonic in the LSB, so the grid is dense below the limit; nothing
coarser than the grid is measured, so nothing coarser is derived); the *suggested* limit is
one grid step finer (near the derived limit the response degrades before it fails). The targets: the limit
``check-config`` accepts (protocol/logical.py) is no coarser than the derived one, so every
accepted resolution on the grid does no harm and compensates; and a DBC with *every* signal at
its accepted limit at once is fine too. Re-run after a change to the control law; a FAIL
names the signal, and the table says which limit to set.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from .. import PROJECT_ROOT
from ..protocol.logical import LOGICAL_SIGNALS
from ..report.metrics import COMPENSATED_RMS_M, RunMetrics, does_harm
from ..scenario import load_scenario
from ..sim.jobs import Job, default_jobs, run_jobs
from ..sim.rescale import native_lsb, rescaled_dbc
from .common import Scorecard, write_json

NAME = "resolution"
HELP = "sweep of field resolutions (position, spool, pressure, currents) × cases 1–3: check-config's limits"

#: the runs judged at each LSB: the paper's cases 1–3 (compensated and no harm) and fault-free
SCENARIOS = ("case1-loe", "case2-drift", "case3-combined", "fault-free")
#: runs where mmac must compensate (≤ oracle + COMPENSATED_RMS_M)
FAULT_SCENARIOS = frozenset(SCENARIOS[:3])
#: the run whose RMS a resolution may raise by at most QUALITY_RMS_M
QUIET_SCENARIO = "fault-free"
#: what a field's resolution may cost the fault-free RMS (m): docs/design.md §11 compares modes
#: within 2 µm; a field may take half of that
QUALITY_RMS_M = 1e-6
MODES = ("nrc", "mmac", "oracle")
#: the scenario seeds each LSB runs with (the noise and the response to it differ per seed)
SEEDS = (1, 2, 3)
#: the row with every signal at its native LSB, and the one with every signal at its limit
NATIVE, ALL_AT_LIMITS = "native", "all at limits"

#: the LSBs swept per logical signal (SI), finest first; the native LSB and the accepted limit
#: are added. Dense below the limits the sweep found (docs/hardware.md §1), coarse beyond;
#: the coarsest is as far as anything is measured.
SWEEP: dict[str, tuple[float, ...]] = {
    "position": (2e-7, 3e-7, 4e-7, 5e-7, 6e-7, 7e-7, 8e-7, 9e-7, 1e-6, 1.5e-6, 2e-6, 3e-6, 5e-6),
    "spool": (1e-7, 2e-7, 5e-7, 6.1e-7, 1e-6, 2e-6, 3e-6, 5e-6, 1e-5, 2e-5),
    "load_pressure": (100.0, 1e3, 2e3, 3e3, 5e3, 7e3, 1e4, 1.5e4, 2e4, 3e4, 5e4, 1e5),
    "coil_current": (5e-7, 1e-6, 1.5e-6, 2e-6, 2.5e-6, 3e-6, 3.5e-6, 4e-6, 4.5e-6, 5e-6, 6e-6, 8e-6, 1e-5),
    "current_setpoint": (1e-6, 2e-6, 3e-6, 4e-6, 5e-6, 6e-6, 8e-6, 1e-5, 1.5e-5, 2e-5, 3e-5, 5e-5),
}
#: how a signal's LSB is printed: (SI per printed unit, unit)
SHOWN: dict[str, tuple[float, str]] = {
    "position": (1e-6, "µm"),
    "spool": (1e-6, "µm"),
    "load_pressure": (1e5, "bar"),
    "coil_current": (1e-6, "µA"),
    "current_setpoint": (1e-6, "µA"),
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--signal", action="append", choices=sorted(SWEEP), help="sweep only this signal (repeatable)"
    )
    p.add_argument(
        "--seeds", type=int, default=len(SEEDS), help=f"seeds per run, 1…{len(SEEDS)} (default all)"
    )
    p.add_argument("--json", metavar="FILE", help="write every row and the limits as JSON")
    p.add_argument("--jobs", "-j", type=int, default=default_jobs(), help="worker processes")


@dataclass(frozen=True)
class Cell:
    """One scenario × seed at one LSB: the three modes' metrics."""

    scenario: str
    seed: int
    nrc: RunMetrics
    mmac: RunMetrics
    oracle: RunMetrics

    def faults(self, native: Cell) -> list[str]:
        """``harm``, ``uncompensated`` and/or ``costly`` (against ``native``, the same run at
        the native LSBs); empty when the cell is fine."""
        out = []
        mm, nrc = self.mmac, self.nrc
        if does_harm(mm, nrc):
            out.append("harm")
        if self.scenario in FAULT_SCENARIOS and mm.rms_error_m > self.oracle.rms_error_m + COMPENSATED_RMS_M:
            out.append("uncompensated")
        if self.scenario == QUIET_SCENARIO and mm.rms_error_m > native.mmac.rms_error_m + QUALITY_RMS_M:
            out.append("costly")
        return out


@dataclass(frozen=True)
class Row:
    """One signal at one LSB (SI; ``key`` :data:`ALL_AT_LIMITS`: every signal at its limit),
    every cell, and what was wrong in each (judged against the native row)."""

    key: str
    lsb: float
    cells: tuple[Cell, ...]
    faults: tuple[tuple[str, ...], ...] = ()

    @property
    def fine(self) -> bool:
        """No cell has harm, is uncompensated or costly."""
        return not any(self.faults)

    def judged(self, native: Row) -> Row:
        """This row with each cell judged against ``native``'s cell of the same run."""
        base = {(c.scenario, c.seed): c for c in native.cells}
        return replace(self, faults=tuple(tuple(c.faults(base[c.scenario, c.seed])) for c in self.cells))

    def worst(self, scenario: str) -> Cell:
        """The cell of ``scenario`` with the largest mmac RMS over the seeds."""
        return max((c for c in self.cells if c.scenario == scenario), key=lambda c: c.mmac.rms_error_m)


def _limit(rows: Sequence[Row], bad: Callable[[tuple[str, ...]], bool]) -> float | None:
    """The largest LSB such that no cell of any row up to it is ``bad`` (None: not the finest)."""
    best = None
    for r in sorted(rows, key=lambda r: r.lsb):
        if any(bad(f) for f in r.faults):
            break
        best = r.lsb
    return best


def derived_limit(rows: Sequence[Row]) -> float | None:
    """The largest LSB such that every swept LSB up to it is fine (None: not even the finest)."""
    return _limit(rows, bool)


def harmless_limit(rows: Sequence[Row]) -> float | None:
    """As :func:`derived_limit` with "no harm" alone as the criterion (figures only)."""
    return _limit(rows, lambda f: "harm" in f)


def accepted_limits() -> dict[str, float]:
    """The coarsest LSB check-config accepts per logical signal (protocol/logical.py)."""
    return {ls.key: ls.resolution for ls in LOGICAL_SIGNALS if ls.resolution is not None}


def grid(key: str) -> tuple[float, ...]:
    """The LSBs swept for ``key``: the native one, :data:`SWEEP`'s and the accepted limit."""
    return tuple(sorted({native_lsb(key), *SWEEP[key], accepted_limits()[key]}))


def _plan(keys: Sequence[str]) -> list[tuple[str, float, dict[str, float]]]:
    """(row key, LSB, the DBC's LSBs by signal) of every row: native first, all at limits last."""
    acc = accepted_limits()
    rows: list[tuple[str, float, dict[str, float]]] = [(NATIVE, math.nan, {})]
    rows += [(k, lsb, {k: lsb}) for k in keys for lsb in grid(k)]
    return [*rows, (ALL_AT_LIMITS, math.nan, {k: acc[k] for k in SWEEP})]


def sweep(keys: Sequence[str], seeds: Sequence[int], n_jobs: int, tmp: Path) -> list[Row]:
    """Every row of :func:`_plan`, judged, run on ``n_jobs`` processes (DBCs written to ``tmp``)."""
    scenarios = [load_scenario(PROJECT_ROOT / "scenarios" / f"{s}.yaml") for s in SCENARIOS]
    plan = _plan(keys)
    jobs = []
    for i, (_, _, lsbs) in enumerate(plan):
        dbc = str(rescaled_dbc(lsbs, tmp / f"{i}.dbc"))
        jobs += [Job(replace(sc, seed=seed), m, dbc=dbc) for sc in scenarios for seed in seeds for m in MODES]
    outcomes = iter(run_jobs(jobs, n_jobs))
    rows = []
    for key, lsb, _ in plan:
        cells = []
        for sc in scenarios:
            for seed in seeds:
                m = {mode: next(outcomes).metrics for mode in MODES}
                cells.append(Cell(sc.name, seed, m["nrc"], m["mmac"], m["oracle"]))
        rows.append(Row(key, lsb, tuple(cells)))
    return [r.judged(rows[0]) for r in rows]


def _lsb(key: str, v: float | None) -> str:
    if v is None:
        return "none"
    if math.isnan(v):
        return ""
    per, unit = SHOWN[key]
    return f"{v / per:.4g} {unit}"


def _print_rows(rows: Sequence[Row]) -> None:
    head = "".join(f" {s + ' mmac RMS/peak (nrc)':>34s}" for s in SCENARIOS)
    print(f"{'signal':16s} {'LSB':>11s}{head}  verdict")
    for r in rows:
        line = f"{r.key:16s} {_lsb(r.key, r.lsb):>11s}"
        for s in SCENARIOS:
            c = r.worst(s)
            line += (
                f" {c.mmac.rms_error_m * 1e6:9.2f}/{c.mmac.max_error_m * 1e6:7.1f}"
                f" ({c.nrc.rms_error_m * 1e6:6.1f}/{c.nrc.max_error_m * 1e6:6.0f})"
            )
        bad = sorted(
            {f"{c.scenario}#{c.seed} {f}" for c, fs in zip(r.cells, r.faults, strict=True) for f in fs}
        )
        print(line + "  " + ("fine" if not bad else ", ".join(bad)))


def _limits(keys: Sequence[str], rows: Sequence[Row], card: Scorecard) -> list[dict[str, object]]:
    """Derived against accepted limit per signal, each a target on ``card``; then the row with
    every signal at its limit."""
    acc = accepted_limits()
    out: list[dict[str, object]] = []
    print(
        f"\n{'signal':16s} {'native':>10s} {'no harm':>10s} {'derived':>10s} {'suggested':>10s} "
        f"{'accepted':>10s}  result"
    )
    for key in keys:
        mine = [r for r in rows if r.key == key]
        lim, harmless = derived_limit(mine), harmless_limit(mine)
        finer = [r.lsb for r in mine if lim is not None and r.lsb < lim * (1 - 1e-9)]
        suggested = max(finer) if finer else lim
        ok = lim is not None and acc[key] <= lim * (1 + 1e-9)
        verdict = card.mark(
            ok, f"{key}: accepted {_lsb(key, acc[key])} is coarser than the derived {_lsb(key, lim)}"
        )
        print(
            f"{key:16s} {_lsb(key, native_lsb(key)):>10s} {_lsb(key, harmless):>10s} "
            f"{_lsb(key, lim):>10s} {_lsb(key, suggested):>10s} {_lsb(key, acc[key]):>10s}  {verdict}"
        )
        out.append(
            {
                "signal": key,
                "no_harm_si": harmless,
                "derived_si": lim,
                "suggested_si": suggested,
                "accepted_si": acc[key],
            }
        )
    every = rows[-1]
    verdict = card.mark(every.fine, "every signal at its accepted limit at once is not fine")
    print(f"{ALL_AT_LIMITS:16s} {'':>54s}  {verdict}")
    return out


def _row_json(r: Row) -> dict[str, object]:
    return {
        "signal": r.key,
        "lsb_si": None if math.isnan(r.lsb) else r.lsb,
        "fine": r.fine,
        "cells": [
            {
                "scenario": c.scenario,
                "seed": c.seed,
                "faults": list(f),
                **{
                    f"{m}_{k}_m": getattr(getattr(c, m), f"{k}_error_m")
                    for m in MODES
                    for k in ("rms", "max")
                },
            }
            for c, f in zip(r.cells, r.faults, strict=True)
        ],
    }


def run(args: argparse.Namespace) -> Scorecard:
    card = Scorecard()
    keys = args.signal or list(SWEEP)
    seeds = SEEDS[: max(1, min(args.seeds, len(SEEDS)))]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="ehpss-resolution-") as tmp:
        rows = sweep(keys, seeds, args.jobs, Path(tmp))
    wall = time.perf_counter() - t0
    print(f"worst over seeds {list(seeds)}; µm; nrc in brackets; harm, uncompensated, costly: the module doc")
    _print_rows(rows)
    limits = _limits(keys, rows, card)
    print(
        f"\n{len(rows)} LSBs × {len(SCENARIOS)} scenarios × {len(seeds)} seeds × {len(MODES)} modes "
        f"in {wall:.0f} s wall on {args.jobs} process(es)"
    )
    write_json(args.json, {"rows": [_row_json(r) for r in rows], "limits": limits})
    return card
