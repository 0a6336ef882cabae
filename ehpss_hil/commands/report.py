"""``ehpss-hil report DIR_or_LOG [--out DIR]``: metrics, figures and ``report.md`` from a CAN log.

Any log python-can reads (candump ``-L``, ``.asc``, ``.blf``, …: the reader ``replay`` uses).
Works from the log alone (its sidecar supplies the reference; ``--scenario`` overrides it); a
log that gives no sample is one line and exit 2.
Metrics are the docs/design.md §10 ones (``ehpss_hil.report.metrics``) when the log has PLANT_TRUTH; the
report states which metrics a log without ground truth can still give.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..canlog.decode import TooLongError
from ..canlog.reader import LogError
from ..extras import require
from ..report.decimate import thinned
from ..report.logdata import LogRun, load_log_run
from ..report.logmetrics import log_metrics
from ..report.markdown import metrics_row, write_markdown
from ..report.streamed import STREAM_ABOVE_BYTES, Loaded, log_bytes, stream_log_run
from ..scenario import Scenario, load_scenario

NAME = "report"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``ehpss-hil report``."""
    p.add_argument(
        "log",
        type=Path,
        help="a log python-can reads (candump -L .log, .asc, .blf, …) or a directory holding one",
    )
    p.add_argument("--out", type=Path, default=None, help="output directory (default: <log dir>/report)")
    p.add_argument(
        "--scenario",
        type=Path,
        default=None,
        help="scenario YAML giving the reference (default: from the sidecar)",
    )
    p.add_argument("--json", type=Path, default=None, help="also write the metrics row here")
    p.add_argument("--no-figures", action="store_true", help="metrics and report.md only")
    p.add_argument(
        "--compare",
        type=Path,
        action="append",
        default=[],
        metavar="LOG",
        help="another run of the scenario (log or directory, repeatable): overlaid in compare.png "
        "(e.g. NRC vs MMAC, as the paper's Figs 4-7) and tabled beside this one",
    )


def _with_samples(run: LogRun) -> LogRun:
    """``run``, or a :class:`LogError` (exit 2) naming its file when it gave no sample."""
    if run.no_samples:
        raise LogError(f"{run.log_path}: no samples: {run.no_samples}")
    return run


def _load(path: Path, scenario: Scenario | None) -> Loaded:
    """A log's report data: whole (:func:`load_log_run`) when it fits in memory, else streamed
    in chunks (:func:`stream_log_run`: its files larger than :data:`STREAM_ABOVE_BYTES`, or more
    samples than :data:`~ehpss_hil.limits.MAX_LOG_SAMPLES`)."""
    if log_bytes(path) <= STREAM_ABOVE_BYTES:
        try:
            lr = _with_samples(load_log_run(path, scenario=scenario))
        except TooLongError:
            pass
        else:
            m = log_metrics(lr)
            drawn = thinned(lr)
            if drawn is not lr:
                lr.notes.append(
                    f"figures drawn from {len(drawn.result.t_s)} of {len(lr.result.t_s)} samples (the "
                    "largest |error| of each bucket); metrics use every sample"
                )
            return Loaded(lr, m, drawn, None, None)
    s = stream_log_run(path, scenario=scenario)
    _with_samples(s.run)
    s.run.notes.append(
        f"a long log, read in chunks: metrics use every sample ({s.metrics.extra['samples']}); "
        f"figures drawn from {len(s.run.result.t_s)} samples (the smallest and largest error and "
        "value of each signal per bucket)"
    )
    return Loaded(s.run, s.metrics, s.run, s.view, s.frame_counts)


def run(args: argparse.Namespace) -> int:
    """Decode, compute, draw, write; prints where everything went."""
    if not args.no_figures:
        require("plot", "the report's figures (or use --no-figures)")
    scenario = load_scenario(args.scenario) if args.scenario is not None else None
    main = _load(args.log, scenario)
    others = [_load(p, scenario) for p in args.compare]
    lr, m = main.run, main.metrics
    out_dir = args.out if args.out is not None else lr.log_path.parent / "report"
    out_dir.mkdir(parents=True, exist_ok=True)
    figures: list[Path] = []
    if not args.no_figures:
        from ..report.logfigures import draw_all, fig_compare

        figures = draw_all(main.drawn, out_dir / "figures", main.view)
        both = fig_compare([main.drawn, *(o.drawn for o in others)], out_dir / "figures")
        figures = [both, *figures] if both is not None else figures
    compare = [(lr, m), *((o.run, o.metrics) for o in others)] if others else None
    md = write_markdown(lr, m, figures, out_dir, compare, main.view, main.frame_counts)
    row = metrics_row(lr, m)
    text = json.dumps([row], indent=1, default=str)
    (out_dir / "metrics.json").write_text(text)
    if args.json is not None:
        args.json.write_text(text)
    for n in lr.notes + [f"not available: {u}" for u in m.unavailable]:
        print(f"note: {n}")
    if m.run is not None:
        print(
            f"RMS error {m.run.rms_error_m * 1e6:.2f} µm, pre-fault max "
            f"{m.run.pre_fault_max_m * 1e6:.2f} µm, switches {m.run.switches}"
        )
    print(f"report: {md} and {md.with_suffix('.html')} (self-contained) ({len(figures)} figures)")
    return 0
