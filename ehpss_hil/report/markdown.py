"""The run report in words: the metric lines of ``report.md`` (and its self-contained HTML
twin, :mod:`.html`) and the JSON row of a log's metrics (shared by ``ehpss-hil report`` and
``ehpss-hil run``). Numbers are written to the resolution they carry: times to the sample (ms),
errors to 0.01 µm, cycle times to the µs; no float is printed raw."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from .annotate import Interval
from .figures import RunView
from .html import write_html
from .logdata import LogRun
from .logfigures import CAPTIONS
from .logmetrics import LogMetrics
from .logviews import log_view


def _um(v: float | None) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—" if v is None or math.isnan(v) else "∞"
    return f"{v * 1e6:.2f} µm"


def _ms(v: float) -> str:
    return "never (∞)" if math.isinf(v) else f"{v * 1e3:.1f} ms"


def _models(active: dict[str, int] | None) -> str:
    return ", ".join(f"{ch} {slot}" for ch, slot in active.items()) if active else "—"


def _versions(v: Any) -> str:
    return ", ".join(f"{k} {val}" for k, val in v.items()) if isinstance(v, dict) else str(v)


def seconds(t: float) -> str:
    """A time on the run's axis to the millisecond (its sample resolution): ``3.502 s``."""
    return f"{t:.3f} s"


def _extra_value(key: str, v: Any) -> str:
    if key.endswith("_s") and isinstance(v, float):
        return f"{v * 1e6:.0f} µs"
    if key.endswith("_m"):
        return _um(v)
    return str(v)


def _words_at(events: list[tuple[float, str]], t: float) -> str:
    """The words of the event at ``t`` (s; the same time list both come from)."""
    near = min(events, key=lambda e: abs(e[0] - t), default=None)
    return near[1] if near is not None and abs(near[0] - t) < 1e-6 else "—"


def _metrics_lines(m: LogMetrics, events: list[tuple[float, str]]) -> list[str]:
    lines = ["## Metrics (docs/design.md §10)", ""]
    if m.run is not None:
        r = m.run
        lines += [
            "| metric | value |",
            "|---|---|",
            f"| RMS error (x − y_m) | {_um(r.rms_error_m)} |",
            f"| pre-fault max error | {_um(r.pre_fault_max_m)} |",
            f"| model switches (seen at CTRL_STATUS rate) | {r.switches} |",
            "",
        ]
        if r.events:
            lines += [
                "| event t (s) | event | peak error (0.3 s) | recovery (< 20 µm) | switches | "
                "active model at end |",
                "|---|---|---|---|---|---|",
            ]
            lines += [
                f"| {e.t_s:.3f} | {_words_at(events, e.t_s)} | {_um(e.peak_error_m)} | {_ms(e.recovery_s)} | "
                f"{e.switches} | {_models(e.active_model)} |"
                for e in r.events
            ]
            lines.append("")
    elif events:  # no metrics (no ground truth): the events alone
        lines += ["| event t (s) | event |", "|---|---|"]
        lines += [f"| {t:.3f} | {words} |" for t, words in events] + [""]
    for u in m.unavailable:
        lines.append(f"- **not available:** {u}")
    if m.unavailable:
        lines.append("")
    lines += ["Also from the log:", ""]
    x = m.extra
    labels = {
        "samples": "controller samples",
        "switches_counter": "model switches (CTRL_STATUS Switches counter)",
        "overruns": "loop overruns (CTRL_STATS)",
        "cycle_time_max_s": "max cycle compute time",
        "sensor_rms_error_m": "sensor-based RMS y_s − y_m (indication only)",
        "x_true_filled_samples": "samples without PLANT_TRUTH (held)",
    }
    for key, label in labels.items():
        if key in x:
            lines.append(f"- {label}: {_extra_value(key, x[key])}")
    lines.append(
        "- frames a live receiver would reject, by verdict (WRONG_SEQUENCE data is still "
        f"used here: the frame itself is intact): {x['rejected_frames'] or 'none'}"
    )
    return [*lines, ""]


def _interval_lines(items: list[Interval]) -> list[str]:
    if not items:
        return []
    lines = ["## Fail-safe and fallback intervals", "", "| from | to | state | reason |", "|---|---|---|---|"]
    lines += [f"| {seconds(iv.t0_s)} | {seconds(iv.t1_s)} | {iv.kind} | {iv.reason or '—'} |" for iv in items]
    return [*lines, ""]


#: the words the figures and tables use without explaining them (docs/design.md §3–5)
GLOSSARY: tuple[tuple[str, str], ...] = (
    ("FRA", "free-running adaptive model: a model whose gain θ is adapted all the time"),
    ("RIA", "reinitialized adaptive model: adapted like FRA, restarted from the active model at a switch"),
    ("θ", "a model's gain parameter: θ_L = k_LOE (spool channel), θ_D = k_DFT (position channel)"),
    (
        "J",
        "performance index of a model: instantaneous plus fading-memory squared residual; the "
        "supervisor selects the smallest",
    ),
    (
        "k̂",
        "the estimate in use of a fault gain (k̂_LOE: loss of valve effectiveness; k̂_DFT: "
        "position-sensor gain, 0 = failed sensor)",
    ),
    ("y_m", "output of the reference model: the motion the loop should follow"),
    (
        "FAULT / fallback",
        "the controller's fail-safe state (with its FailsafeReason) / the loop "
        "held on nominal compensation by the do-no-harm monitor (with its FallbackReason)",
    ),
)


def _figure_lines(figures: list[Path], out_dir: Path) -> list[str]:
    """Each figure with its caption (an italic line under the image; report.html turns the pair
    into a figure with a caption), then the glossary."""
    if not figures:
        return []
    lines = ["## Figures", ""]
    for n, p in enumerate(figures, 1):
        caption = CAPTIONS.get(p.stem, p.stem)
        lines += [f"![{p.stem}]({p.relative_to(out_dir).as_posix()})", f"*Figure {n}: {caption}*", ""]
    lines += ["## Glossary", ""] + [f"- **{term}**: {words}" for term, words in GLOSSARY]
    return [*lines, ""]


def _compare_lines(runs: list[tuple[LogRun, LogMetrics]]) -> list[str]:
    if len(runs) < 2:
        return []
    lines = [
        "## Modes compared",
        "",
        "| mode | RMS error | pre-fault max | worst event peak | longest recovery | switches | log |",
        "|---|---|---|---|---|---|---|",
    ]
    for lr, m in runs:
        r = m.run
        if r is None:
            lines.append(f"| {lr.result.controller} | — | — | — | — | — | `{lr.log_path}` |")
            continue
        peak = max((e.peak_error_m for e in r.events), default=0.0)
        rec = max((e.recovery_s for e in r.events), default=0.0)
        lines.append(
            f"| {r.controller} | {_um(r.rms_error_m)} | {_um(r.pre_fault_max_m)} | {_um(peak)} | "
            f"{_ms(rec)} | {r.switches} | `{lr.log_path}` |"
        )
    return [*lines, ""]


def write_markdown(
    run: LogRun,
    m: LogMetrics,
    figures: list[Path],
    out_dir: Path,
    compare: list[tuple[LogRun, LogMetrics]] | None = None,
    view: RunView | None = None,
    frame_counts: dict[str, int] | None = None,
) -> Path:
    """``report.md`` in ``out_dir`` embedding ``figures`` (relative links), and ``report.html``
    beside it with the figures inside (one file to send). ``compare``: this run and the runs
    it was overlaid with, for a table of their metrics. ``view`` and ``frame_counts``: the
    events, intervals and frames decoded of the whole log when ``run`` holds a thinned part
    of it (:mod:`.streamed`; default: from ``run``)."""
    view = view if view is not None else log_view(run)
    r, side = run.result, run.sidecar or {}
    counts = frame_counts or {n: len(f["t_s"]) for n, f in run.frames.items()}
    frames = ", ".join(f"{n} {c}" for n, c in sorted(counts.items()))
    n_samples = m.extra.get("samples", len(r.t_s))
    lines = [
        f"# Run report: {r.scenario} / {r.controller}",
        "",
        f"- log: `{run.log_path}` ({n_samples} samples at Ts = {r.ts_s * 1e3:g} ms)",
        f"- sidecar: {'yes' if run.sidecar else 'none'}; started "
        f"{side.get('start_time_utc', '?')}; versions {_versions(side.get('versions', '?'))}",
        f"- DBC sha256: {(side.get('dbc') or {}).get('sha256', '?')}",
        f"- ground truth (PLANT_TRUTH): {'yes' if run.has_truth else 'NO'}; reference: "
        f"{'yes' if run.has_reference else 'NO'}",
        "- events: " + ("; ".join(f"{words} at {seconds(t)}" for t, words in view.events) or "none"),
        f"- frames decoded: {frames}",
        "",
    ]
    if run.notes:
        lines += ["## Notes", ""] + [f"- {n}" for n in run.notes] + [""]
    lines += _compare_lines(compare or [])
    lines += _metrics_lines(m, view.events)
    lines += _interval_lines(view.intervals)
    lines += _figure_lines(figures, out_dir)
    path = out_dir / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    write_html(lines, out_dir, path.with_suffix(".html"), title=f"Run report: {r.scenario} / {r.controller}")
    return path


def metrics_row(run: LogRun, m: LogMetrics) -> dict[str, object]:
    """The docs/design.md §10 JSON row (plus ``extra`` and ``unavailable``)."""
    row: dict[str, object] = (
        m.run.to_json()
        if m.run is not None
        else {"scenario": run.result.scenario, "controller": run.result.controller}
    )
    row["extra"] = m.extra
    row["unavailable"] = m.unavailable
    return row
