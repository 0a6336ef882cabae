"""Metrics (docs/design.md §10) of an ``ehpss-hil run`` directory, from its bus log, and whether
its realtime figures are valid (:mod:`ehpss_hil.runtime.rtverdict`, from the processes' exit
summaries)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from .errors import OutputError
from .report.logdata import load_log_run
from .report.logmetrics import log_metrics
from .report.markdown import metrics_row, write_markdown
from .runtime.rtverdict import RealtimeVerdict, judge
from .scenario import Scenario, load_scenario


def loses_frames(sc: Scenario) -> bool:
    """The scenario drops frames on purpose somewhere (its watchdog trips are then its own)."""
    return any(loss.sensor > 0.0 or loss.command > 0.0 for _k, _f, loss in sc.fault_timeline())


def _summary(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def run_verdict(
    out_dir: Path, meta: dict[str, Any] | None = None, sc: Scenario | None = None
) -> RealtimeVerdict:
    """Whether the run in ``out_dir`` held the rate: its ``run.json`` (lockstep, steal) and the
    two processes' ``*-summary.json``. A run without the controller's summary is not valid."""
    meta = meta if meta is not None else json.loads((out_dir / "run.json").read_text())
    sc = sc if sc is not None else load_scenario(meta["scenario_path"])
    if meta.get("lockstep"):
        return judge({}, None, sc.sample_time_s, lockstep=True)
    ctl = _summary(out_dir / "controller-summary.json")
    if ctl is None:
        return RealtimeVerdict(False, ["no controller-summary.json: the controller's timing is unknown"])
    return judge(
        ctl,
        _summary(out_dir / "emulator-summary.json"),
        sc.sample_time_s,
        frame_loss=loses_frames(sc),
        steal_fraction=meta.get("host_steal_fraction"),
    )


def metrics_from_run(out_dir: Path, plot: bool = False, written: list[Path] | None = None) -> dict[str, Any]:
    """Decode ``out_dir/bus.log`` with the run's scenario; write ``metrics.json`` (a one-row
    list, docs/design.md §10 format) and, with ``plot``, the report figures and ``report/report.md``
    (each file written is appended to ``written``). The row carries ``realtime_valid`` and
    ``realtime_reasons`` (:func:`run_verdict`). A file that cannot be written is an
    :class:`~ehpss_hil.errors.OutputError`."""
    meta = json.loads((out_dir / "run.json").read_text())
    sc = load_scenario(meta["scenario_path"])
    lr = load_log_run(out_dir / "bus.log", scenario=sc)
    m = log_metrics(lr)
    row = metrics_row(lr, m)
    row["controller"] = meta["mode"]
    row["scenario"] = sc.name
    row.update(run_verdict(out_dir, meta, sc).to_json())
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


def _um(v: Any) -> str:
    return "—" if not isinstance(v, int | float) or not math.isfinite(v) else f"{v * 1e6:.2f} µm"


def _event(e: dict[str, Any]) -> str:
    rec = e.get("recovery_s")
    rec_txt = "never" if rec is None or math.isinf(rec) else f"{rec * 1e3:.0f} ms"
    return f"{e['t_s']:.2f} s: peak {_um(e.get('peak_error_m'))}, recovery {rec_txt}"


def describe(row: dict[str, Any]) -> list[str]:
    """A metrics row in a few lines of text (the JSON stays in ``metrics.json``)."""
    lines = [
        f"{row.get('scenario')} {row.get('controller')}: RMS {_um(row.get('rms_error_m'))}, "
        f"pre-fault max {_um(row.get('pre_fault_max_m'))}, switches {row.get('switches', '—')}"
    ]
    events = row.get("events") or []
    if events:
        lines.append("events: " + "; ".join(_event(e) for e in events))
    rejected = (row.get("extra") or {}).get("rejected_frames") or {}
    if rejected:
        lines.append("rejected frames: " + ", ".join(f"{k} {n}" for k, n in rejected.items()))
    if row.get("unavailable"):
        lines.append("not in the log: " + ", ".join(map(str, row["unavailable"])))
    return lines
