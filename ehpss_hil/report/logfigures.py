"""PNG figures of one logged run, like the paper's Figs 4–7 (matplotlib, imported lazily).

Each function takes a :class:`~ehpss_hil.report.logdata.LogRun` and its
:class:`~ehpss_hil.report.figures.RunView`, draws one figure into ``out_dir`` and returns its path
(None when the log holds nothing to draw). Fault events are dashed lines named above the top
axis, FAULT and fallback intervals are shaded with their reason, samples without ground truth
are gaps over a grey band, legends sit outside the axes. Plotted in mm, µm and mA; computed in
SI.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..extras import require
from .figures import RunView, estimating, has_estimator, mark_events, plot_runs, shade
from .logdata import LogRun
from .logviews import log_view
from .metrics import RECOVERY_BAND_M

#: CTRL_INDEX slot names (ehpss_hil.control.controllers docstring)
SLOT_NAMES = {
    0: "spool k_LOE=1",
    1: "spool k_LOE=0.5",
    2: "spool FRA",
    3: "spool RIA",
    4: "pos k_DFT=1",
    5: "pos k_DFT=0.5",
    6: "pos k_DFT=0 (failed)",
    7: "pos FRA",
    8: "pos RIA",
    9: "joint nominal",
    10: "joint LOE 50 %",
    11: "joint drift 0.5",
    12: "joint FRA",
    13: "joint RIA",
    14: "smac adaptive",
    15: "slot 15",
}


def pyplot() -> Any:
    """``matplotlib.pyplot`` with the file-only Agg backend, or a
    :class:`~ehpss_hil.errors.MissingExtraError` naming the ``plot`` extra."""
    require("plot", "figures (or use --no-figures)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _figure(view: RunView, n_axes: int = 1, height: float = 3.2) -> tuple[Any, list[Any]]:
    plt = pyplot()
    fig, axes = plt.subplots(
        n_axes, 1, figsize=(10.5, height * n_axes + 0.4), sharex=True, squeeze=False, layout="constrained"
    )
    axs = list(axes[:, 0])
    for ax in axs:
        ax.grid(True, alpha=0.3)
    axs[-1].set_xlabel("t (s)")
    return fig, axs


def _legend(ax: Any, fontsize: int = 8) -> None:
    """The axis's legend outside it, on the right (never over data)."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=fontsize, frameon=False)


def _save(fig: Any, out_dir: Path, name: str, view: RunView) -> Path:
    axs = fig.axes
    mark_events(axs, view.events)
    shade(axs, [view], several=False)
    title = axs[0].get_title()
    if title and view.events:  # room for the events' names between the title and the axis
        axs[0].set_title(title, pad=26)
    for ax in axs:
        n = len(ax.get_legend_handles_labels()[1])
        if n:
            _legend(ax, 7 if n > 8 else 8)
    path = out_dir / name
    fig.savefig(path, dpi=110)
    pyplot().close(fig)
    return path


def fig_position(run: LogRun, out_dir: Path, view: RunView) -> Path | None:
    """Piston position vs the reference model (Fig 4 style), mm."""
    r = run.result
    if len(r.t_s) == 0:
        return None
    fig, (ax,) = _figure(view, 1, 3.6)
    if run.has_reference:
        ax.plot(r.t_s, r.x_d_m * 1e3, color="0.6", lw=0.8, label="x_d (reference)")
        ax.plot(r.t_s, r.y_m_m * 1e3, "k--", lw=1.0, label="y_m (reference model)")
    if run.has_truth:
        ax.plot(
            r.t_s, np.where(view.counted, r.x_true_m, np.nan) * 1e3, "C0", lw=1.0, label="x (PLANT_TRUTH)"
        )
    ax.plot(r.t_s, r.y_s_m * 1e3, "C1", lw=0.6, alpha=0.7, label="y_s (position sensor)")
    ax.set_ylabel("position (mm)")
    ax.set_title(f"{r.scenario} / {r.controller}: position vs reference model")
    return _save(fig, out_dir, "position.png", view)


def fig_error(run: LogRun, out_dir: Path, view: RunView) -> Path | None:
    """Tracking error x − y_m with the ±20 µm recovery band (Fig 5 style), µm."""
    r = run.result
    if not run.has_reference or len(r.t_s) == 0:
        return None
    fig, (ax,) = _figure(view)
    if run.has_truth:
        ax.plot(r.t_s, np.where(view.counted, r.error_m, np.nan) * 1e6, "C0", lw=0.8, label="e = x − y_m")
    else:
        ax.plot(
            r.t_s,
            (r.y_s_m - r.y_m_m) * 1e6,
            "C1",
            lw=0.8,
            label="y_s − y_m (sensor-based: no ground truth in this log)",
        )
    band = RECOVERY_BAND_M * 1e6
    ax.axhspan(-band, band, color="C2", alpha=0.15, label="±20 µm")
    ax.set_ylabel("error (µm)")
    ax.set_title("tracking error")
    return _save(fig, out_dir, "error.png", view)


def fig_current(run: LogRun, out_dir: Path, view: RunView) -> Path | None:
    """Valve coil current: VALVE_CMD setpoint and the applied current echo, mA."""
    r = run.result
    if len(r.t_s) == 0:
        return None
    fig, (ax,) = _figure(view)
    ax.plot(r.t_s, run.commanded_current_a * 1e3, "C3", lw=0.8, label="VALVE_CMD setpoint")
    ax.plot(r.t_s, r.current_a * 1e3, "k", lw=0.5, alpha=0.6, label="applied (SENSOR_AUX echo)")
    ax.set_ylabel("current (mA)")
    ax.set_title("valve current")
    return _save(fig, out_dir, "current.png", view)


def fig_models(run: LogRun, out_dir: Path, view: RunView) -> Path | None:
    """Active model slot per channel (CTRL_STATUS, Fig 6 style); none for a mode without an
    estimator (its slot never moves)."""
    r = run.result
    if "CTRL_STATUS" not in run.frames or len(r.t_s) == 0 or not has_estimator(r.controller):
        return None
    fig, (ax,) = _figure(view)
    ax.step(r.t_s, r.active_spool, where="post", label="spool channel")
    if not np.array_equal(r.active_spool, r.active_position):
        ax.step(r.t_s, r.active_position, where="post", label="position channel")
    used = sorted({int(v) for v in np.concatenate((r.active_spool, r.active_position)) if v >= 0})
    ax.set_yticks(used, [f"{s}: {SLOT_NAMES.get(s, s)}" for s in used], fontsize=7)
    ax.set_title("active model (CTRL_STATUS)")
    return _save(fig, out_dir, "models.png", view)


def fig_estimates(run: LogRun, out_dir: Path, view: RunView) -> Path | None:
    """k̂_LOE and k̂_DFT against the true fault gains (PLANT_FAULTS), gaps in FAULT; the true
    gains alone for a mode without an estimator."""
    r = run.result
    if "CTRL_STATUS" not in run.frames and "PLANT_FAULTS" not in run.frames:
        return None
    estimates, est = has_estimator(r.controller), estimating(view)
    if not estimates and not np.any(np.isfinite(r.true_k_loe)):
        return None
    fig, axs = _figure(view, 2, 2.6)
    for ax, hat, true, lab in (
        (axs[0], r.k_loe_hat, r.true_k_loe, "k_LOE"),
        (axs[1], r.k_dft_hat, r.true_k_dft, "k_DFT"),
    ):
        if estimates:
            ax.plot(r.t_s, np.where(est, hat, np.nan), "C0", lw=1.0, label=f"{lab} estimate (CTRL_STATUS)")
        if np.any(np.isfinite(true)):
            ax.step(r.t_s, true, "k--", where="post", lw=1.0, label=f"true {lab}")
        ax.set_ylabel(lab)
    if np.any(np.isfinite(r.true_k_q)) and np.any(r.true_k_q[np.isfinite(r.true_k_q)] != 1.0):
        axs[0].step(r.t_s, r.true_k_q, "C3:", where="post", label="true k_Q")
    axs[0].set_title(
        "estimates vs true faults" if estimates else f"true faults ({r.controller}: no estimator)"
    )
    return _save(fig, out_dir, "estimates.png", view)


def fig_index(run: LogRun, out_dir: Path, view: RunView) -> Path | None:
    """Performance index J per model slot (CTRL_INDEX, Fig 7 style), log scale."""
    r = run.result
    cols = [s for s in range(r.index.shape[1]) if np.any(np.isfinite(r.index[:, s]))]
    if not cols:
        return None
    fig, (ax,) = _figure(view, 1, 3.8)
    for s in cols:
        j = r.index[:, s]
        ax.semilogy(r.t_s, np.where(j > 0, j, np.nan), lw=0.9, label=f"{s}: {SLOT_NAMES[s]}")
    ax.set_ylabel("J")
    ax.set_title("performance index per model (CTRL_INDEX)")
    return _save(fig, out_dir, "index.png", view)


#: the caption under each figure in report.md / report.html, by file stem
CAPTIONS: dict[str, str] = {
    "overview": "The run at a glance: (a) piston position x against the reference x_d and the "
    "reference model y_m; (b) tracking error; (c) coil current; (d) active model slot; (e) the "
    "estimates k̂ against the true fault gains.",
    "compare": "The modes of one scenario overlaid (the same panels as the overview); a mode "
    "without an estimator (NRC) has no k̂ or model trace.",
    "position": "Piston position x (PLANT_TRUTH) and the sensor reading y_s against the reference "
    "model output y_m, mm.",
    "error": "Tracking error e = x − y_m, µm; the green band is the ±20 µm recovery band of the "
    "recovery times.",
    "current": "Coil current: the controller's setpoint (VALVE_CMD) and what the amplifier "
    "applied (SENSOR_AUX), mA.",
    "models": "The model slot the supervisor uses per channel (CTRL_STATUS); a switch is a step.",
    "estimates": "The estimates k̂_LOE and k̂_DFT in use against the fault gains the emulator "
    "applied (PLANT_FAULTS).",
    "index": "The performance index J of each model slot (CTRL_INDEX), log scale: the "
    "supervisor selects the smallest J, with hysteresis.",
}

FIGURES: tuple[Callable[[LogRun, Path, RunView], Path | None], ...] = (
    fig_position,
    fig_error,
    fig_current,
    fig_models,
    fig_estimates,
    fig_index,
)


def fig_overview(run: LogRun, out_dir: Path, view: RunView) -> Path | None:
    """The shared 5-panel run figure (:func:`ehpss_hil.report.figures.plot_runs`, the one ``sim``
    draws), fed with the log's per-sample arrays."""
    if len(run.result.t_s) == 0:
        return None
    pyplot()  # the clear error first when matplotlib is missing
    title = f"{run.result.scenario} — {run.result.controller} (from {run.log_path.name})"
    if not run.has_truth:
        title += ": no PLANT_TRUTH in this log"
    return plot_runs([view], out_dir / "overview.png", title=title)


def fig_compare(runs: list[LogRun], out_dir: Path, name: str = "compare.png") -> Path | None:
    """Several logged runs of one scenario overlaid (NRC vs MMAC, as the paper's Figs 4–7)."""
    runs = [r for r in runs if len(r.result.t_s)]
    if len(runs) < 2:
        return None
    pyplot()
    views = [log_view(r) for r in runs]
    modes = " vs ".join(v.label for v in views)
    return plot_runs(views, out_dir / name, title=f"{runs[0].result.scenario} — {modes}")


def draw_all(run: LogRun, out_dir: Path, view: RunView | None = None) -> list[Path]:
    """Every figure the log allows (the shared overview first); returns the PNG paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    v = view if view is not None else log_view(run)
    return [p for f in (fig_overview, *FIGURES) if (p := f(run, out_dir, v)) is not None]
