"""The campaign's verdicts: per fault class the share of runs compensated and of harm, the worst
runs (each written as a scenario file ``ehpss-hil sim`` reruns exactly), and ``summary.md``.

compensated: mmac RMS ≤ oracle RMS + :data:`~ehpss_hil.report.metrics.COMPENSATED_RMS_M`;
harm: mmac RMS > :data:`~ehpss_hil.report.metrics.NO_HARM_RATIO` · nrc RMS +
:data:`~ehpss_hil.report.metrics.NO_HARM_RMS_M`. The worst runs are listed twice, by two
orders that answer two questions: by **harm**, mmac − nrc RMS (what the reconfiguration costs
against the plain loop: a run it made worse), and by **gap**, mmac − oracle RMS (what is left to
gain against compensating the true faults). A run of 0.7 µm where the oracle holds 0.1 µm and a
run of 716 µm where nrc holds 300 µm are both "worst", for different reasons.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..report.metrics import COMPENSATED_RMS_M, NO_HARM_RATIO, NO_HARM_RMS_M, harm_rms_limit_m
from .sampling import RunPlan
from .scenario_file import write_scenario

#: worst runs listed (and written as scenario files) per fault class and overall, per order
WORST_N = 5
WORST_DIR = "worst"
#: the two orders of the worst runs: name → the RMS difference it sorts by, largest first
ORDERS: dict[str, str] = {"harm": "mmac − nrc", "gap": "mmac − oracle"}


@dataclass
class Worst:
    """One worst run: index, fault class, RMS per mode (m), its scenario file (once written)."""

    index: int
    fault_class: str
    rms_m: dict[str, float]
    #: its scenario file per order it is listed in (once written)
    paths: dict[str, Path] = field(default_factory=dict)

    @property
    def harm_m(self) -> float:
        """mmac RMS − nrc RMS (m): > 0, the reconfiguration made the run worse."""
        return self.rms_m["mmac"] - self.rms_m["nrc"]

    @property
    def gap_m(self) -> float:
        """mmac RMS − oracle RMS (m): what is left to gain."""
        return self.rms_m["mmac"] - self.rms_m["oracle"]

    def key_m(self, order: str) -> float:
        """The difference ``order`` (``harm`` or ``gap``) sorts by (m)."""
        return self.harm_m if order == "harm" else self.gap_m


@dataclass
class ClassSummary:
    """The verdicts of one fault class."""

    fault_class: str
    runs: int = 0
    compensated: int = 0
    harm: int = 0
    #: the runs of the class, then the worst :data:`WORST_N` by harm (mmac − nrc, largest first)
    worst_harm: list[Worst] = field(default_factory=list)
    #: … and by gap (mmac − oracle, largest first)
    worst_gap: list[Worst] = field(default_factory=list)

    def worst(self, order: str) -> list[Worst]:
        """The worst runs by ``order`` (``harm`` or ``gap``)."""
        return self.worst_harm if order == "harm" else self.worst_gap

    @property
    def compensated_pct(self) -> float:
        """Share of runs compensated (%)."""
        return 100.0 * self.compensated / self.runs if self.runs else math.nan

    @property
    def harm_pct(self) -> float:
        """Share of runs with harm (%)."""
        return 100.0 * self.harm / self.runs if self.runs else math.nan


def is_compensated(mmac_m: float, oracle_m: float) -> bool:
    """mmac RMS within :data:`COMPENSATED_RMS_M` of the oracle's (m)."""
    return mmac_m <= oracle_m + COMPENSATED_RMS_M


def is_harm(mmac_m: float, nrc_m: float) -> bool:
    """mmac RMS beyond the do-no-harm bound of nrc's (m)."""
    return mmac_m > harm_rms_limit_m(nrc_m)


def summarize(rows: Sequence[dict[str, Any]], modes: Sequence[str]) -> list[ClassSummary]:
    """Per fault class (most runs first), and ``all`` last."""
    classes: dict[str, ClassSummary] = {}
    total = ClassSummary("all")
    for r in rows:
        mm, orc, nrc = r["mmac.rms_error_m"], r["oracle.rms_error_m"], r["nrc.rms_error_m"]
        rms = {m: r[f"{m}.rms_error_m"] for m in modes}
        for cs in (classes.setdefault(r["fault_class"], ClassSummary(r["fault_class"])), total):
            cs.runs += 1
            cs.compensated += is_compensated(mm, orc)
            cs.harm += is_harm(mm, nrc)
            cs.worst_harm.append(Worst(r["index"], r["fault_class"], rms))  # its own paths per class
    out = [*sorted(classes.values(), key=lambda c: (-c.runs, c.fault_class)), total]
    for cs in out:
        runs = cs.worst_harm
        cs.worst_harm = sorted(runs, key=lambda w: (-w.harm_m, w.index))[:WORST_N]
        cs.worst_gap = sorted(runs, key=lambda w: (-w.gap_m, w.index))[:WORST_N]
    return out


def write_worst(summaries: Sequence[ClassSummary], plans: Sequence[RunPlan], out: Path) -> list[Path]:
    """Write each listed worst run's scenario as ``worst/<class>/<order>-<rank>-run<index>.yaml``
    (order ``harm`` or ``gap``); returns the paths written."""
    by_index = {p.index: p for p in plans}
    written = []
    for cs in summaries:
        for order in ORDERS:
            for rank, w in enumerate(cs.worst(order), 1):
                name = f"{order}-{rank}-run{w.index:05d}.yaml"
                path = write_scenario(by_index[w.index].scenario, out / WORST_DIR / cs.fault_class / name)
                w.paths[order] = path
                written.append(path)
    return written


def summary_json(summaries: Sequence[ClassSummary]) -> dict[str, Any]:
    """The per-class figures as JSON (``summary.json``; RMS in m, the worst runs by harm and by
    gap with their index)."""
    return {
        "classes": [
            {
                "fault_class": cs.fault_class,
                "runs": cs.runs,
                "compensated_pct": cs.compensated_pct,
                "harm_pct": cs.harm_pct,
                **{
                    f"worst_{order}": [
                        {"index": w.index, f"{order}_m": w.key_m(order), "rms_m": w.rms_m}
                        for w in cs.worst(order)
                    ]
                    for order in ORDERS
                },
            }
            for cs in summaries
        ]
    }


def model_error_section(rows: Sequence[dict[str, Any]], ranges: dict[str, tuple[float, float]]) -> list[str]:
    """summary.md's "Model error" lines: per sampled plant key its range and, for the runs whose
    |relative error| is at most the median and for those above it, the shares compensated and
    with harm (%)."""
    md = [
        "## Model error",
        "",
        "The emulated plant's keys were drawn per run as relative errors around the base plant;",
        "the controller kept configs/params.yaml (plant ≠ model in every run).",
        "",
        "| plant key | range % | runs | small error: comp % / harm % | large error: comp % / harm % |",
        "|---|---|---:|---|---|",
    ]
    for key, (lo, hi) in ranges.items():
        errs = sorted(abs(r[f"model_error.{key}"]) for r in rows)
        median = errs[(len(errs) - 1) // 2] if errs else 0.0
        halves = (
            [r for r in rows if abs(r[f"model_error.{key}"]) <= median],
            [r for r in rows if abs(r[f"model_error.{key}"]) > median],
        )
        cells = []
        for part in halves:
            n = len(part)
            comp = sum(is_compensated(r["mmac.rms_error_m"], r["oracle.rms_error_m"]) for r in part)
            harm = sum(is_harm(r["mmac.rms_error_m"], r["nrc.rms_error_m"]) for r in part)
            cells.append(f"{100 * comp / n:.1f} / {100 * harm / n:.1f} ({n})" if n else "–")
        md.append(f"| {key} | {100 * lo:+g} … {100 * hi:+g} | {len(rows)} | {cells[0]} | {cells[1]} |")
    return [*md, ""]


def _um(x: float) -> str:
    return f"{x * 1e6:.1f}"


def _top(cs: ClassSummary, order: str) -> str:
    """``run 12: +3.4`` — the worst run by ``order`` and its difference (µm); empty: no run."""
    w = cs.worst(order)
    return f"run {w[0].index}: {w[0].key_m(order) * 1e6:+.1f}" if w else ""


def format_summary(summaries: Sequence[ClassSummary]) -> str:
    """The per-class table as fixed-width text (stdout)."""
    harm, gap = (f"{'most harm' if o == 'harm' else 'largest gap'} ({ORDERS[o]} µm)" for o in ORDERS)
    head = f"{'fault class':26s} {'runs':>5s} {'comp %':>7s} {'harm %':>7s}  {harm:24s}  {gap}"
    lines = [head, "-" * len(head)]
    for cs in summaries:
        lines.append(
            f"{cs.fault_class[:26]:26s} {cs.runs:5d} {cs.compensated_pct:7.1f} {cs.harm_pct:7.1f}  "
            f"{_top(cs, 'harm'):24s}  {_top(cs, 'gap')}"
        )
    return "\n".join(lines)


def summary_markdown(
    title: str,
    header: Sequence[str],
    summaries: Sequence[ClassSummary],
    figures: Sequence[Path],
    out: Path,
    sections: Sequence[str] = (),
) -> str:
    """summary.md: the campaign, the per-class table, ``sections`` (lines, e.g. the model error),
    the worst five per class by harm and by gap, the figures."""
    md = [f"# Campaign {title}", "", *header, ""]
    md += [
        f"compensated: mmac RMS ≤ oracle RMS + {_um(COMPENSATED_RMS_M)} µm; harm: mmac RMS > "
        f"{NO_HARM_RATIO:g} × nrc RMS + {_um(NO_HARM_RMS_M)} µm.",
        "",
        "| fault class | runs | compensated % | harm % | most harm: run (mmac − nrc µm) "
        "| largest gap: run (mmac − oracle µm) |",
        "|---|---:|---:|---:|---|---|",
    ]
    for cs in summaries:
        md.append(
            f"| {cs.fault_class} | {cs.runs} | {cs.compensated_pct:.1f} | {cs.harm_pct:.1f} "
            f"| {_top(cs, 'harm')} | {_top(cs, 'gap')} |"
        )
    md += ["", *sections]
    for order, heading in (("harm", "Most harm"), ("gap", "Largest gap to the oracle")):
        md += _worst_section(summaries, order, heading, out)
    if figures:
        md += ["## Figures", ""] + [f"![{f.stem}]({f.relative_to(out)})" for f in figures] + [""]
    return "\n".join(md)


def _worst_section(summaries: Sequence[ClassSummary], order: str, title: str, out: Path) -> list[str]:
    """summary.md's list of the worst five per class by ``order``."""
    md = [
        f"## {title} ({ORDERS[order]} RMS), five per class",
        "",
        f"Largest {ORDERS[order]} first; rerun one with `ehpss-hil sim FILE -C nrc -C mmac -C oracle`.",
        "",
    ]
    for cs in summaries:
        md += [
            f"### {cs.fault_class}",
            "",
            f"| run | {ORDERS[order]} µm | mmac µm | oracle µm | nrc µm | scenario |",
            "|---:|---:|---:|---:|---:|---|",
        ]
        for w in cs.worst(order):
            path = w.paths.get(order)
            rel = path.relative_to(out) if path else ""
            rms = " | ".join(_um(w.rms_m[m]) for m in ("mmac", "oracle", "nrc"))
            md.append(f"| {w.index} | {w.key_m(order) * 1e6:+.1f} | {rms} | {rel} |")
        md.append("")
    return md
