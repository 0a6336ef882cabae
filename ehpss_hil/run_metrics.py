"""Metrics (docs/design.md §10) of an ``ehpss-hil run`` directory, from its bus log alone."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .errors import OutputError
from .report.logdata import load_log_run, log_metrics
from .report.markdown import metrics_row, write_markdown
from .scenario import load_scenario


def metrics_from_run(out_dir: Path, plot: bool = False, written: list[Path] | None = None) -> dict[str, Any]:
    """Decode ``out_dir/bus.log`` with the run's scenario; write ``metrics.json`` (a one-row
    list, docs/design.md §10 format) and, with ``plot``, the report figures and ``report/report.md``
    (each file written is appended to ``written``). A file that cannot be written is an
    :class:`~ehpss_hil.errors.OutputError`."""
    meta = json.loads((out_dir / "run.json").read_text())
    sc = load_scenario(meta["scenario_path"])
    lr = load_log_run(out_dir / "bus.log", scenario=sc)
    m = log_metrics(lr)
    row = metrics_row(lr, m)
    row["controller"] = meta["mode"]
    row["scenario"] = sc.name
    written = written if written is not None else []
    try:
        (out_dir / "metrics.json").write_text(json.dumps([row], indent=1, default=str) + "\n")
        written.append(out_dir / "metrics.json")
        if plot:
            from .report.logfigures import draw_all

            rep = out_dir / "report"
            figs = draw_all(lr, rep / "figures")
            written += figs
            md = write_markdown(lr, m, figs, rep)
            written += [md, md.with_suffix(".html")]
    except OSError as exc:
        (out_dir / "metrics.json").unlink(missing_ok=True)
        raise OutputError(f"{out_dir}: cannot write the metrics: {exc.strerror or exc}") from exc
    return row
