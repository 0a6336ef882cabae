"""``ehpss-hil bench control``: control quality of every mode on the shipped and unseen scenarios,
each docs/design.md §11 target printed with PASS/FAIL beside the measured figure."""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from .. import PROJECT_ROOT, native
from ..control.registry import MODES
from ..control.tuning import ControlTuning
from ..report.metrics import COMPENSATED_RMS_M, RunMetrics, does_harm, harm_limits
from ..scenario import _FAULT_KEYS, load_scenario
from ..sim.jobs import Job, default_jobs, run_jobs, scenario_paths
from ..sim.lockstep import run_scenario
from .common import Scorecard, write_json

NAME = "control"
HELP = "control quality of nrc/smac/mmac-paper/mmac/oracle against the docs/design.md §11 targets"

SHIPPED = ("fault-free", "case1-loe", "case2-drift", "case3-combined", "case4-disturbance")
UNSEEN = (
    "unseen-loe35",
    "unseen-drift1p4",
    "unseen-combined",
    "unseen-noise1pct",
    "unseen-frameloss2pct",
    "unseen-blackouts",
)
KQ = "kq-loss"
#: scenarios/envelope/: steps, waves, fast and large motions, power-on faults, faults while
#: holding still, a current limit, a quiet run (the "do no harm" family)
ENVELOPE_DIR = "envelope"
QUIET = "quiet-20s"
#: fault-free envelope runs: mmac RMS within this of nrc (m); power-on faults: ≤ oracle + this
FAULT_FREE_RMS_M = 1e-6
POWER_ON_RMS_M = COMPENSATED_RMS_M
QUIET_SWITCHES = 2
SPEED_TARGET = 50.0
#: the speed rows time these mmac runs one at a time in this process, after the pools: two runs
#: sharing this host's two vCPUs slowed each other from 71× to 46× (2026-11-28), which is the
#: host's figure, not the code's per core. Each run is timed ``SPEED_REPEATS`` times and its
#: fastest kept (a host's hiccup only ever slows a run); the row is the median run.
SPEED_LINEAR = SHIPPED
SPEED_REPEATS = 2
#: a fault at or before this time (s) counts as present at power-on
POWER_ON_S = 0.1
#: the rows on the plant = model (shipped, unseen, envelope): the controller's params are the
#: plant's, as after commissioning (``identify``), so it is told its model is exact; the plant ≠
#: model family runs with the default tuning (docs/control.md §9.1)
COMMISSIONED = ControlTuning(pressure_gain_uncertainty=0.0, velocity_gain_uncertainty=0.0)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", metavar="FILE", help="write the metric rows and verdicts as JSON")
    p.add_argument("--jobs", "-j", type=int, default=default_jobs(), help="worker processes")


@dataclass
class Verdict:
    """One target line: what, the measured figure, the target, pass or fail (None: info only)."""

    what: str
    measured: str
    target: str
    ok: bool | None


Table = dict[tuple[str, str], RunMetrics]

#: the plant ≠ model family: scenarios/mismatch/ (the linear plant off params.yaml, faults and
#: none) and scenarios/plant/ (the nonlinear plant); the controller keeps params.yaml
MISMATCH_DIRS = ("mismatch", "plant")
#: … fault runs compensated in at least this share (issue #27's target within ±20 %)
MISMATCH_COMPENSATED = 0.8


def _um(v: float) -> str:
    return f"{v * 1e6:.2f} µm"


def _ms(v: float) -> str:
    return "never" if math.isinf(v) else f"{v * 1e3:.0f} ms"


def _fault_free(t: Table) -> list[Verdict]:
    return [
        Verdict(
            f"fault-free RMS, {m}",
            _um(t["fault-free", m].rms_error_m),
            "≤ 3 µm",
            t["fault-free", m].rms_error_m <= 3e-6,
        )
        for m in MODES
    ]


def _vs_oracle(t: Table) -> list[Verdict]:
    out = []
    for sc in ("case1-loe", "case3-combined"):
        mm, orc = t[sc, "mmac"].rms_error_m, t[sc, "oracle"].rms_error_m
        out.append(Verdict(f"{sc} mmac RMS", _um(mm), f"≤ oracle + 5 = {_um(orc + 5e-6)}", mm <= orc + 5e-6))
    return out


def _case2(t: Table) -> list[Verdict]:
    m = t["case2-drift", "mmac"]
    fail_peak = m.events[-1].peak_error_m if m.events else math.nan
    other = min(t["case2-drift", "smac"].rms_error_m, t["case2-drift", "mmac-paper"].rms_error_m)
    return [
        Verdict("case2-drift mmac RMS", _um(m.rms_error_m), "≤ 10 µm", m.rms_error_m <= 1e-5),
        Verdict("case2-drift peak after sensor failure", _um(fail_peak), "≤ 10 µm", fail_peak <= 1e-5),
        Verdict(
            "case2-drift mmac vs best of smac/mmac-paper",
            f"{other / m.rms_error_m:.3g}× better",
            "≥ 2×",
            other >= 2 * m.rms_error_m,
        ),
    ]


def _case4(t: Table) -> list[Verdict]:
    mm, nrc = t["case4-disturbance", "mmac"].rms_error_m, t["case4-disturbance", "nrc"].rms_error_m
    return [
        Verdict(
            "case4-disturbance mmac RMS", _um(mm), f"≤ 100 µm and < nrc {_um(nrc)}", mm <= 1e-4 and mm < nrc
        )
    ]


def _others(t: Table) -> list[Verdict]:
    out = []
    for sc in ("fault-free", "case1-loe", "case3-combined", "case4-disturbance"):
        mm = t[sc, "mmac"].rms_error_m
        best = min(t[sc, "smac"].rms_error_m, t[sc, "mmac-paper"].rms_error_m)
        out.append(
            Verdict(
                f"{sc} mmac vs better of smac/mmac-paper", _um(mm), f"≤ {_um(best)} + 2 µm", mm <= best + 2e-6
            )
        )
    return out


def _recovery(t: Table, scenarios: tuple[str, ...]) -> list[Verdict]:
    worst_rec, worst_sw, where = 0.0, 0, ""
    for sc in scenarios:
        if (sc, "mmac") not in t:
            continue
        for em, eo in zip(t[sc, "mmac"].events, t[sc, "oracle"].events, strict=True):
            if math.isfinite(eo.recovery_s) and em.recovery_s > worst_rec:
                worst_rec, where = em.recovery_s, f"{sc} @ {em.t_s:g} s"
            worst_sw = max(worst_sw, em.switches)
    return [
        Verdict(
            f"worst mmac recovery where oracle recovers ({where or 'all events'})",
            _ms(worst_rec),
            "≤ 20 ms",
            worst_rec <= 0.02,
        ),
        Verdict("most mmac switches in one fault event", str(worst_sw), "≤ 10", worst_sw <= 10),
    ]


def _unseen(t: Table) -> list[Verdict]:
    return [
        Verdict(
            f"{sc} mmac RMS", _um(t[sc, "mmac"].rms_error_m), "≤ 20 µm", t[sc, "mmac"].rms_error_m <= 2e-5
        )
        for sc in UNSEEN
        if (sc, "mmac") in t
    ]


def _kq(t: Table) -> list[Verdict]:
    if (KQ, "mmac") not in t:
        return []
    mm, nrc = t[KQ, "mmac"].rms_error_m, t[KQ, "nrc"].rms_error_m
    return [
        Verdict(
            "k_Q loss mmac RMS (goal: no worse than nrc)",
            f"{_um(mm)} ({mm / nrc:.2g}× nrc {_um(nrc)})",
            "≤ nrc (goal)",
            mm <= nrc,
        )
    ]


def timed_speeds(paths: Sequence[str | Path], tuning: ControlTuning | None = None) -> list[float]:
    """mmac's speed (simulated s per s of loop CPU time) on each scenario of ``paths``, run alone
    in this process, the fastest of ``SPEED_REPEATS`` runs each."""
    out = []
    for p in paths:
        sc = load_scenario(p)
        out.append(max(run_scenario(sc, "mmac", tuning=tuning).speed for _ in range(SPEED_REPEATS)))
    return out


def _speed(plants: dict[str, list[float]]) -> list[Verdict]:
    """One row per plant model (``plants``: model → the speeds of its timed runs): the median,
    in loop CPU time on one core; the row says whether the controller ran compiled."""
    how = "compiled" if native.compiled() else "from source"
    rows = []
    for model, speeds in plants.items():
        sp = sorted(speeds)
        med = sp[len(sp) // 2] if sp else 0.0
        rows.append(
            Verdict(
                f"mmac sim speed, {model} plant (median of {len(sp)} runs alone, {how})",
                f"{med:.0f}× real time",
                f"≥ {SPEED_TARGET:.0f}×",
                med >= SPEED_TARGET,
            )
        )
    return rows


def _no_harm(t: Table) -> list[Verdict]:
    """mmac against nrc on every scenario of the table (envelope, shipped, unseen)."""
    out = []
    for sc in sorted({s for s, _ in t}):
        if (sc, "mmac") not in t or (sc, "nrc") not in t:
            continue
        mm, nrc = t[sc, "mmac"], t[sc, "nrc"]
        lim, plim = harm_limits(nrc)
        out.append(
            Verdict(
                f"no harm: {sc} mmac RMS / worst",
                f"{_um(mm.rms_error_m)} / {_um(mm.max_error_m)}",
                f"≤ {_um(lim)} / {_um(plim)}",
                mm.rms_error_m <= lim and mm.max_error_m <= plim,
            )
        )
    return out


def _envelope(t: Table, envelope: dict[str, str]) -> list[Verdict]:
    """Fault-free envelope runs: mmac ≈ nrc; power-on faults: mmac ≈ oracle; the quiet run."""
    out = []
    for sc, kind in sorted(envelope.items()):
        mm = t[sc, "mmac"]
        if kind == "fault-free":
            ref = t[sc, "nrc"].rms_error_m
            out.append(
                Verdict(
                    f"fault-free {sc} mmac RMS",
                    _um(mm.rms_error_m),
                    f"≤ nrc + 1 = {_um(ref + FAULT_FREE_RMS_M)}",
                    mm.rms_error_m <= ref + FAULT_FREE_RMS_M,
                )
            )
        elif kind == "power-on":
            ref = t[sc, "oracle"].rms_error_m
            out.append(
                Verdict(
                    f"power-on {sc} mmac RMS",
                    _um(mm.rms_error_m),
                    f"≤ oracle + 5 = {_um(ref + POWER_ON_RMS_M)}",
                    mm.rms_error_m <= ref + POWER_ON_RMS_M,
                )
            )
    if QUIET in envelope:
        sw = t[QUIET, "mmac"].switches
        out.append(Verdict(f"{QUIET} mmac switches", str(sw), f"≤ {QUIET_SWITCHES}", sw <= QUIET_SWITCHES))
    return out


def verdicts(t: Table, envelope: dict[str, str] | None = None) -> list[Verdict]:
    """Every docs/design.md §11 control target evaluated on the campaign table, then the envelope's
    ("do no harm") targets; ``envelope``: envelope scenario name → ``fault-free``,
    ``power-on`` or ``other``."""
    env = envelope or {}
    return (
        _fault_free(t)
        + _vs_oracle(t)
        + _case2(t)
        + _case4(t)
        + _others(t)
        + _recovery(t, SHIPPED[1:] + UNSEEN)
        + _unseen(t)
        + _kq(t)
        + _envelope(t, env)
        + _no_harm(t)
    )


def envelope_kinds(paths: list[Path]) -> dict[str, str]:
    """Envelope scenario name → ``fault-free`` (no events), ``power-on`` (a fault at t ≤ warm-up
    of 0.1 s) or ``other``."""
    out = {}
    for p in paths:
        sc = load_scenario(p)
        faults = [e for e in sc.events if any(getattr(e, k) is not None for k in _FAULT_KEYS)]
        if not faults:
            out[sc.name] = "fault-free"
        elif faults[0].t_s <= POWER_ON_S:
            out[sc.name] = "power-on"
        else:
            out[sc.name] = "other"
    return out


def format_verdicts(vs: list[Verdict], card: Scorecard) -> str:
    """The one table: target, measured, limit, PASS/FAIL (each marked on ``card``)."""
    w = max(len(v.what) for v in vs)
    lines = [f"{'target':{w}s}  {'measured':>28s}  {'limit':30s}  result", "-" * (w + 72)]
    for v in vs:
        res = card.mark(v.ok, f"{v.what} {v.measured.strip()} (limit {v.target})") or "info"
        lines.append(f"{v.what:{w}s}  {v.measured:>28s}  {v.target:30s}  {res}")
    return "\n".join(lines)


def _progress() -> Callable[[int, int], None] | None:
    if not sys.stderr.isatty():
        return None

    def show(done: int, total: int) -> None:
        sys.stderr.write(f"\r  {done}/{total} runs" + ("\n" if done == total else ""))
        sys.stderr.flush()

    return show


def _mismatch(t: Table, family: dict[str, bool]) -> list[Verdict]:
    """The plant ≠ model family (``family``: scenario name → has a fault event): no harm in any
    run (the per-run rows are in :func:`_no_harm`), and the faults compensated (mmac ≤ oracle +
    ``COMPENSATED_RMS_M``, or ≤ half of nrc where the oracle, blind to the model error, is
    off) in at least :data:`MISMATCH_COMPENSATED` of the fault runs."""
    runs = [sc for sc in sorted(family) if (sc, "mmac") in t and (sc, "nrc") in t]
    if not runs:
        return []
    harmed = [sc for sc in runs if does_harm(t[sc, "mmac"], t[sc, "nrc"])]
    faulty = [sc for sc in runs if family[sc] and (sc, "oracle") in t]
    comp = [
        sc
        for sc in faulty
        if t[sc, "mmac"].rms_error_m <= t[sc, "oracle"].rms_error_m + COMPENSATED_RMS_M
        or t[sc, "mmac"].rms_error_m <= 0.5 * t[sc, "nrc"].rms_error_m
    ]
    share = len(comp) / len(faulty) if faulty else 1.0
    return [
        Verdict(
            "plant ≠ model family: runs with harm",
            f"{len(harmed)} of {len(runs)}",
            "= 0",
            not harmed,
        ),
        Verdict(
            "plant ≠ model family: fault runs compensated",
            f"{100 * share:.0f} % ({len(comp)} of {len(faulty)})",
            f"≥ {100 * MISMATCH_COMPENSATED:.0f} %",
            share >= MISMATCH_COMPENSATED,
        ),
    ]


def _family(paths: list[Path]) -> dict[str, bool]:
    """Scenario name → whether it has a fault event."""
    out = {}
    for p in paths:
        sc = load_scenario(p)
        out[sc.name] = bool(sc.events)
    return out


def run(args: argparse.Namespace) -> Scorecard:
    card = Scorecard()
    sdir = PROJECT_ROOT / "scenarios"
    env_paths = sorted((sdir / ENVELOPE_DIR).glob("*.yaml"))
    mm_paths = sorted(p for d in MISMATCH_DIRS for p in (sdir / d).glob("*.yaml"))
    nominal = scenario_paths(
        [sdir / f"{n}.yaml" for n in SHIPPED]
        + [sdir / "extra" / f"{n}.yaml" for n in (*UNSEEN, KQ)]
        + env_paths
    )
    jobs = [Job(p, m) for p in nominal for m in MODES]
    family = [Job(p, m) for p in scenario_paths(mm_paths) for m in MODES]
    t0 = time.perf_counter()
    outcomes = run_jobs(jobs, args.jobs, tuning=COMMISSIONED, progress=_progress())
    outcomes += run_jobs(family, args.jobs, progress=_progress())
    jobs += family
    wall = time.perf_counter() - t0
    table: Table = {(o.metrics.scenario, o.metrics.controller): o.metrics for o in outcomes}
    nonlinear = [p for p in scenario_paths(mm_paths) if load_scenario(p).plant.model == "nonlinear"]
    speeds = {
        "linear": timed_speeds([sdir / f"{n}.yaml" for n in SPEED_LINEAR], COMMISSIONED),
        "nonlinear": timed_speeds(nonlinear),
    }
    vs = verdicts(table, envelope_kinds(env_paths)) + _speed(speeds) + _mismatch(table, _family(mm_paths))
    print(format_verdicts(vs, card))
    simulated = sum(o.metrics.duration_s for o in outcomes)
    print(
        f"\n{len(jobs)} runs, {simulated:.0f} s simulated in {wall:.1f} s wall on "
        f"{min(args.jobs, len(jobs))} process(es): {wall / simulated * 1e3:.1f} ms wall per "
        f"simulated second ({simulated / wall:.0f}× real time)"
    )
    write_json(
        args.json, {"rows": [o.metrics.to_json() for o in outcomes], "targets": [v.__dict__ for v in vs]}
    )
    return card
