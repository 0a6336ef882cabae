"""The campaign's verdicts: per fault class the share of runs compensated and of harm, the worst
runs (each written as a scenario file ``ehpss-hil sim`` reruns exactly), and ``summary.md``.

compensated: mmac RMS ≤ oracle RMS + :data:`~ehpss_hil.report.metrics.COMPENSATED_RMS_M`;
harm: mmac RMS > :data:`~ehpss_hil.report.metrics.NO_HARM_RATIO` · nrc RMS +
:data:`~ehpss_hil.report.metrics.NO_HARM_RMS_M`. The worst runs are those where mmac loses the
most RMS to the oracle (mmac − oracle).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..report.metrics import COMPENSATED_RMS_M, NO_HARM_RATIO, NO_HARM_RMS_M
from .sampling import RunPlan
from .scenario_file import write_scenario

#: worst runs listed (and written as scenario files) per fault class and overall
WORST_N = 5
WORST_DIR = "worst"


@dataclass
class Worst:
    """One worst run: index, fault class, RMS per mode (m), its scenario file (once written)."""

    index: int
    fault_class: str
    rms_m: dict[str, float]
    path: Path | None = None

    @property
    def excess_m(self) -> float:
        """mmac RMS − oracle RMS (m)."""
        return self.rms_m["mmac"] - self.rms_m["oracle"]


@dataclass
class ClassSummary:
    """The verdicts of one fault class."""

    fault_class: str
    runs: int = 0
    compensated: int = 0
    harm: int = 0
    worst: list[Worst] = field(default_factory=list)

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
    return mmac_m > NO_HARM_RATIO * nrc_m + NO_HARM_RMS_M


def summarize(rows: Sequence[dict[str, Any]], modes: Sequence[str]) -> list[ClassSummary]:
    """Per fault class (most runs first), and ``all`` last."""
    classes: dict[str, ClassSummary] = {}
    total = ClassSummary("all")
    for r in rows:
        mm, orc, nrc = r["mmac.rms_error_m"], r["oracle.rms_error_m"], r["nrc.rms_error_m"]
        w = Worst(r["index"], r["fault_class"], {m: r[f"{m}.rms_error_m"] for m in modes})
        for cs in (classes.setdefault(r["fault_class"], ClassSummary(r["fault_class"])), total):
            cs.runs += 1
            cs.compensated += is_compensated(mm, orc)
            cs.harm += is_harm(mm, nrc)
            cs.worst.append(w)
    out = [*sorted(classes.values(), key=lambda c: (-c.runs, c.fault_class)), total]
    for cs in out:
        cs.worst = sorted(cs.worst, key=lambda w: (-w.excess_m, w.index))[:WORST_N]
    return out


def write_worst(summaries: Sequence[ClassSummary], plans: Sequence[RunPlan], out: Path) -> list[Path]:
    """Write each listed worst run's scenario as ``worst/<class>/<rank>-run<index>.yaml``;
    returns the paths written."""
    by_index = {p.index: p for p in plans}
    written = []
    for cs in summaries:
        for rank, w in enumerate(cs.worst, 1):
            name = f"{rank}-run{w.index:05d}.yaml"
            w.path = write_scenario(by_index[w.index].scenario, out / WORST_DIR / cs.fault_class / name)
            written.append(w.path)
    return written


def summary_json(summaries: Sequence[ClassSummary]) -> dict[str, Any]:
    """The per-class figures as JSON (``summary.json``; RMS in m, worst runs by index)."""
    return {
        "classes": [
            {
                "fault_class": cs.fault_class,
                "runs": cs.runs,
                "compensated_pct": cs.compensated_pct,
                "harm_pct": cs.harm_pct,
                "worst": [{"index": w.index, "rms_m": w.rms_m} for w in cs.worst],
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


def format_summary(summaries: Sequence[ClassSummary]) -> str:
    """The per-class table as fixed-width text (stdout)."""
    head = (
        f"{'fault class':26s} {'runs':>5s} {'comp %':>7s} {'harm %':>7s}  worst (run: mmac/oracle/nrc RMS µm)"
    )
    lines = [head, "-" * len(head)]
    for cs in summaries:
        worst = "; ".join(
            f"{w.index}: {_um(w.rms_m['mmac'])}/{_um(w.rms_m['oracle'])}/{_um(w.rms_m['nrc'])}"
            for w in cs.worst[:2]
        )
        lines.append(
            f"{cs.fault_class[:26]:26s} {cs.runs:5d} {cs.compensated_pct:7.1f} {cs.harm_pct:7.1f}  {worst}"
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
    the worst five per class, the figures."""
    md = [f"# Campaign {title}", "", *header, ""]
    md += [
        f"compensated: mmac RMS ≤ oracle RMS + {_um(COMPENSATED_RMS_M)} µm; harm: mmac RMS > "
        f"{NO_HARM_RATIO:g} × nrc RMS + {_um(NO_HARM_RMS_M)} µm.",
        "",
        "| fault class | runs | compensated % | harm % | worst run (mmac / oracle / nrc RMS µm) |",
        "|---|---:|---:|---:|---|",
    ]
    for cs in summaries:
        w = cs.worst[0] if cs.worst else None
        worst = (
            f"{w.index}: {_um(w.rms_m['mmac'])} / {_um(w.rms_m['oracle'])} / {_um(w.rms_m['nrc'])}"
            if w
            else ""
        )
        md.append(
            f"| {cs.fault_class} | {cs.runs} | {cs.compensated_pct:.1f} | {cs.harm_pct:.1f} | {worst} |"
        )
    md += ["", *sections]
    md += [
        "## Worst five per class",
        "",
        "mmac − oracle RMS, largest first; rerun one with `ehpss-hil sim FILE -C nrc -C mmac -C oracle`.",
        "",
    ]
    for cs in summaries:
        md += [
            f"### {cs.fault_class}",
            "",
            "| run | mmac µm | oracle µm | nrc µm | scenario |",
            "|---:|---:|---:|---:|---|",
        ]
        for w in cs.worst:
            rel = w.path.relative_to(out) if w.path else ""
            rms = " | ".join(_um(w.rms_m[m]) for m in ("mmac", "oracle", "nrc"))
            md.append(f"| {w.index} | {rms} | {rel} |")
        md.append("")
    if figures:
        md += ["## Figures", ""] + [f"![{f.stem}]({f.relative_to(out)})" for f in figures] + [""]
    return "\n".join(md)
