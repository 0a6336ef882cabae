"""One campaign session: plan the runs, skip those the journal holds, run the rest (local or Dask),
then write the table, the worst cases, the figures and summary.md.

Output directory (``--out``): ``runs.jsonl`` (the journal), ``results.parquet`` (+ ``.csv``),
``summary.md``, ``worst/<class>/*.yaml``, the figures, and the manifest of
:mod:`ehpss_hil.outputs` listing them. A directory that holds a journal is only continued with
``resume``; without it the campaign refuses to touch it (exit 2). A file at one of those names
that the manifest does not list (a user's ``summary.md``) is refused the same way unless
``overwrite``, which replaces those names only.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..canlog.sidecar import write_json_atomic
from ..errors import OutputError
from ..outputs import MANIFEST, exists, foreign, manifest_files, refuse_foreign, write_manifest
from .executors import Executor, Tally, open_executor
from .figures import FIGURE_NAMES, write_figures
from .journal import JOURNAL_NAME, Expected, Journal, read_journal
from .progress import Progress
from .runs import METRIC_COLUMNS, RunTask
from .sampling import RunPlan, plan_runs
from .spec import Campaign, tuning_overrides
from .summary import (
    WORST_DIR,
    ClassSummary,
    model_error_section,
    summarize,
    summary_json,
    summary_markdown,
    write_worst,
)
from .table import CSV_NAME, PARQUET_NAME, build_rows, to_table, write_table

SUMMARY_NAME = "summary.md"
SUMMARY_JSON_NAME = "summary.json"
#: the tool named in a campaign directory's manifest
TOOL = "ehpss-hil campaign"


def campaign_file_names() -> list[str]:
    """The fixed names a campaign writes in its directory (the worst cases not included)."""
    names = [JOURNAL_NAME, PARQUET_NAME, CSV_NAME, SUMMARY_NAME, SUMMARY_JSON_NAME, *FIGURE_NAMES]
    return [*names, *(f"{n}.tmp" for n in names if n != JOURNAL_NAME)]


@dataclass
class Outcome:
    """What a session did: runs planned, skipped (found in the journal), run now; the rows and
    summaries (empty when interrupted) and the files written."""

    planned: int
    skipped: int
    ran: int = 0
    #: wall time of executing the runs (s), without planning and writing
    run_wall_s: float = 0.0
    rows: list[dict[str, Any]] = field(default_factory=list)
    summaries: list[ClassSummary] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    #: timing of the runs done now (from their records)
    timings: list[dict[str, Any]] = field(default_factory=list)
    #: where the runs went, and the workers lost and runs retried there
    executor: str = ""
    tally: Tally = field(default_factory=Tally)


def prepare_out(out: Path, resume: bool, overwrite: bool = False) -> Path:
    """Make ``out``; refuse one holding a journal unless ``resume``, and files at the campaign's
    names it did not write unless ``overwrite``; record the names in its manifest."""
    journal = out / JOURNAL_NAME
    if exists(journal) and not resume and not _empty(journal):
        raise OutputError(
            f"{out} holds a campaign's runs ({JOURNAL_NAME}); pass --resume or choose another --out"
        )
    try:
        out.mkdir(parents=True, exist_ok=True)
        listed = manifest_files(out, TOOL)
        if listed is None and resume and exists(journal):  # a campaign of before the manifest
            listed = [*campaign_file_names(), *_worst_files(out)]
        ours = set(listed or []) | ({MANIFEST} if listed is not None else set())
        names = [out / n for n in (MANIFEST, *campaign_file_names())]  # another tool's manifest too
        if not overwrite:
            refuse_foreign(
                out, foreign([*names, *(out / n for n in _worst_files(out))], ours, out), "the campaign"
            )
        write_manifest(out, TOOL, (ours - {MANIFEST}) | set(campaign_file_names()))
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"cannot prepare {out}: {exc.strerror or exc}") from exc
    return journal


def _empty(path: Path) -> bool:
    """``path`` is a regular file of 0 bytes (a journal of a session that ran nothing)."""
    return path.is_file() and not path.is_symlink() and path.stat().st_size == 0


def _worst_files(out: Path) -> list[str]:
    """The files under ``out/worst`` (relative to ``out``), symlinks included, not followed."""
    root = out / WORST_DIR
    if not root.is_dir() or root.is_symlink():
        return [WORST_DIR] if exists(root) else []
    return sorted(str(p.relative_to(out)) for p in root.rglob("*") if p.is_symlink() or not p.is_dir())


def record_files(out: Path, paths: list[Path]) -> None:
    """Add ``paths`` (inside ``out``) to its manifest (OutputError when it cannot be written)."""
    listed = set(manifest_files(out, TOOL) or [])
    try:
        write_manifest(out, TOOL, listed | {str(p.relative_to(out)) for p in paths})
    except OSError as exc:
        raise OutputError(f"cannot write the manifest of {out}: {exc.strerror or exc}") from exc


def run_campaign(
    camp: Campaign,
    out: Path,
    workers: int = 1,
    scheduler: str | None = None,
    resume: bool = False,
    csv: bool = False,
    figures: bool = True,
    progress: Progress | None = None,
    overwrite: bool = False,
    executor: Executor | None = None,
) -> Outcome:
    """Run the campaign into ``out`` (see the module docstring) on ``executor`` (default: the
    one of ``workers`` and ``scheduler``, opened before ``out`` is touched). KeyboardInterrupt
    propagates after the journal is closed: every run that finished is kept."""
    with open_executor(workers, scheduler) if executor is None else nullcontext(executor) as ex:
        return _run(camp, out, ex, resume, csv, figures, progress, overwrite)


def _run(
    camp: Campaign,
    out: Path,
    ex: Executor,
    resume: bool,
    csv: bool,
    figures: bool,
    progress: Progress | None,
    overwrite: bool,
) -> Outcome:
    journal_path = prepare_out(out, resume, overwrite)
    plans = plan_runs(camp)
    columns = [f"{m}.{c}" for m in camp.spec.modes for c in METRIC_COLUMNS]
    expected = Expected({p.run_hash: p.index for p in plans}, frozenset(columns))
    with Journal(journal_path) as journal:
        records = read_journal(journal_path, expected)
        todo = [p for p in plans if p.run_hash not in records]
        outcome = Outcome(len(plans), len(plans) - len(todo), executor=ex.description)
        prog = progress if progress is not None else Progress(len(plans), outcome.skipped)
        prog.tally = outcome.tally
        tasks = [
            RunTask(p.index, p.run_hash, p.scenario, camp.spec.modes, camp.spec.transport, camp.spec.tuning)
            for p in todo
        ]

        def on_result(rec: dict[str, Any]) -> None:
            journal.append(rec)
            records[rec["run_hash"]] = rec
            outcome.ran += 1
            outcome.timings.append(rec["timing"])
            prog.step()

        t0 = time.perf_counter()
        try:
            ex.run(tasks, on_result, outcome.tally)
        finally:
            outcome.run_wall_s = time.perf_counter() - t0
            prog.finish()
    finish(camp, plans, records, out, outcome, csv, figures)
    return outcome


def finish(
    camp: Campaign,
    plans: list[RunPlan],
    records: dict[str, dict[str, Any]],
    out: Path,
    outcome: Outcome,
    csv: bool,
    figures: bool,
) -> None:
    """Table, worst cases, figures and summary.md from the finished records."""
    rows = build_rows(plans, records)
    outcome.rows = rows
    outcome.files += write_table(to_table(rows), out, csv)
    outcome.summaries = summarize(rows, camp.spec.modes)
    record_files(out, write_worst(outcome.summaries, plans, out))
    figs = write_figures(rows, camp.spec.modes, out) if figures else []
    outcome.files += figs
    spec = camp.spec
    header = [
        f"{spec.description}" if spec.description else "",
        f"- file: `{camp.source}`, content hash `{camp.content_hash[:16]}`",
        f"- {len(rows)} runs of {camp.duration_s:g} s, sampler {spec.sampler}, modes {', '.join(spec.modes)}",
        "- table: `results.parquet` (one row per run; columns `<mode>.<metric>`)",
    ]
    if outcome.ran:
        trouble = outcome.tally.detail()
        header.append(
            f"- {outcome.ran} runs executed now on {outcome.executor}" + (f": {trouble}" if trouble else "")
        )
    changed = tuning_overrides(spec.tuning)
    header.append(f"- controller tuning: {changed or 'the defaults'}")
    sections: list[str] = []
    if spec.model_error is not None:
        ranges = spec.model_error.ranges()
        text = ", ".join(f"{k} {100 * lo:+g} … {100 * hi:+g} %" for k, (lo, hi) in ranges.items())
        model = spec.model_error.model or camp.base.plant.model
        header.append(f"- model error (plant ≠ model, columns `model_error.<key>`): {model} plant, {text}")
        sections = model_error_section(rows, ranges)
    path = out / SUMMARY_NAME
    try:
        path.write_text(summary_markdown(spec.name, header, outcome.summaries, figs, out, sections))
        write_json_atomic(out / SUMMARY_JSON_NAME, summary_json(outcome.summaries))
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    outcome.files += [path, out / SUMMARY_JSON_NAME]
