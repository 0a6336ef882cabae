"""PNG figures of one logged run, like the paper's Figs 4–7 (matplotlib, imported lazily).

Each function takes a :class:`~ehpss_hil.report.logdata.LogRun`, draws one figure into
``out_dir`` and returns its path (None when the log holds nothing to draw). Fault event times are
dashed vertical lines. Plotted in mm, µm and mA; computed in SI.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import EhpssError
from .logdata import LogRun
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


class PlotUnavailableError(EhpssError, ImportError):
    """matplotlib is not installed (it is the optional ``plot`` extra)."""


def pyplot() -> Any:
    """``matplotlib.pyplot`` with the file-only Agg backend, or a clear error."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise PlotUnavailableError(
            "figures need matplotlib: pip install 'ehpss-hil[plot]' (or use --no-figures)"
        ) from exc
    return plt


def _figure(run: LogRun, n_axes: int = 1, height: float = 3.2) -> tuple[Any, list[Any]]:
    plt = pyplot()
    fig, axes = plt.subplots(n_axes, 1, figsize=(9, height * n_axes), sharex=True, squeeze=False)
    axs = list(axes[:, 0])
    for ax in axs:
        for t in run.result.event_times_s:
            ax.axvline(t, color="0.5", ls="--", lw=0.8)
        ax.grid(True, alpha=0.3)
    axs[-1].set_xlabel("t (s)")
    return fig, axs


def _save(fig: Any, out_dir: Path, name: str) -> Path:
    path = out_dir / name
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)
    return path


def fig_position(run: LogRun, out_dir: Path) -> Path | None:
    """Piston position vs the reference model (Fig 4 style), mm."""
    r = run.result
    if len(r.t_s) == 0:
        return None
    fig, (ax,) = _figure(run, 1, 3.6)
    if run.has_reference:
        ax.plot(r.t_s, r.x_d_m * 1e3, color="0.6", lw=0.8, label="x_d (reference)")
        ax.plot(r.t_s, r.y_m_m * 1e3, "k--", lw=1.0, label="y_m (reference model)")
    if run.has_truth:
        ax.plot(r.t_s, r.x_true_m * 1e3, "C0", lw=1.0, label="x (PLANT_TRUTH)")
    ax.plot(r.t_s, r.y_s_m * 1e3, "C1", lw=0.6, alpha=0.7, label="y_s (position sensor)")
    ax.set_ylabel("position (mm)")
    ax.set_title(f"{r.scenario} / {r.controller}: position vs reference model")
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, out_dir, "position.png")


def fig_error(run: LogRun, out_dir: Path) -> Path | None:
    """Tracking error x − y_m with the ±20 µm recovery band (Fig 5 style), µm."""
    r = run.result
    if not run.has_reference or len(r.t_s) == 0:
        return None
    fig, (ax,) = _figure(run)
    if run.has_truth:
        ax.plot(r.t_s, r.error_m * 1e6, "C0", lw=0.8, label="e = x − y_m")
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
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, out_dir, "error.png")


def fig_current(run: LogRun, out_dir: Path) -> Path | None:
    """Valve coil current: VALVE_CMD setpoint and the applied current echo, mA."""
    r = run.result
    if len(r.t_s) == 0:
        return None
    fig, (ax,) = _figure(run)
    ax.plot(r.t_s, run.commanded_current_a * 1e3, "C3", lw=0.8, label="VALVE_CMD setpoint")
    ax.plot(r.t_s, r.current_a * 1e3, "k", lw=0.5, alpha=0.6, label="applied (SENSOR_AUX echo)")
    ax.set_ylabel("current (mA)")
    ax.set_title("valve current")
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, out_dir, "current.png")


def fig_models(run: LogRun, out_dir: Path) -> Path | None:
    """Active model slot per channel (CTRL_STATUS, Fig 6 style)."""
    r = run.result
    if "CTRL_STATUS" not in run.frames or len(r.t_s) == 0:
        return None
    fig, (ax,) = _figure(run)
    ax.step(r.t_s, r.active_spool, where="post", label="spool channel")
    if not np.array_equal(r.active_spool, r.active_position):
        ax.step(r.t_s, r.active_position, where="post", label="position channel")
    used = sorted({int(v) for v in np.concatenate((r.active_spool, r.active_position)) if v >= 0})
    ax.set_yticks(used, [f"{s}: {SLOT_NAMES.get(s, s)}" for s in used], fontsize=7)
    ax.set_title("active model (CTRL_STATUS)")
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, out_dir, "models.png")


def fig_estimates(run: LogRun, out_dir: Path) -> Path | None:
    """k̂_LOE and k̂_DFT against the true fault gains (PLANT_FAULTS)."""
    r = run.result
    if "CTRL_STATUS" not in run.frames and "PLANT_FAULTS" not in run.frames:
        return None
    fig, axs = _figure(run, 2, 2.6)
    for ax, hat, true, lab in (
        (axs[0], r.k_loe_hat, r.true_k_loe, "k_LOE"),
        (axs[1], r.k_dft_hat, r.true_k_dft, "k_DFT"),
    ):
        ax.plot(r.t_s, hat, "C0", lw=1.0, label=f"{lab} estimate (CTRL_STATUS)")
        if np.any(np.isfinite(true)):
            ax.step(r.t_s, true, "k--", where="post", lw=1.0, label=f"true {lab}")
        ax.set_ylabel(lab)
        ax.legend(loc="lower left", fontsize=8)
    if np.any(np.isfinite(r.true_k_q)) and np.any(r.true_k_q[np.isfinite(r.true_k_q)] != 1.0):
        axs[0].step(r.t_s, r.true_k_q, "C3:", where="post", label="true k_Q")
        axs[0].legend(loc="lower left", fontsize=8)
    axs[0].set_title("estimates vs true faults")
    return _save(fig, out_dir, "estimates.png")


def fig_index(run: LogRun, out_dir: Path) -> Path | None:
    """Performance index J per model slot (CTRL_INDEX, Fig 7 style), log scale."""
    r = run.result
    cols = [s for s in range(r.index.shape[1]) if np.any(np.isfinite(r.index[:, s]))]
    if not cols:
        return None
    fig, (ax,) = _figure(run, 1, 3.8)
    for s in cols:
        j = r.index[:, s]
        ax.semilogy(r.t_s, np.where(j > 0, j, np.nan), lw=0.9, label=f"{s}: {SLOT_NAMES[s]}")
    ax.set_ylabel("J")
    ax.set_title("performance index per model (CTRL_INDEX)")
    ax.legend(loc="upper right", fontsize=7, ncol=2)
    return _save(fig, out_dir, "index.png")


FIGURES: tuple[Callable[[LogRun, Path], Path | None], ...] = (
    fig_position,
    fig_error,
    fig_current,
    fig_models,
    fig_estimates,
    fig_index,
)


def fig_overview(run: LogRun, out_dir: Path) -> Path | None:
    """The shared 5-panel run figure of :func:`ehpss_hil.report.figures.plot_run` (the same one
    ``sim`` and ``bench`` draw), fed with the log's per-sample arrays."""
    if len(run.result.t_s) == 0:
        return None
    pyplot()  # the clear error first when matplotlib is missing
    from .figures import plot_run

    title = f"{run.result.scenario} — {run.result.controller} (from {run.log_path.name})"
    if not run.has_truth:
        title += ": no PLANT_TRUTH in this log"
    return plot_run(run.result, out_dir / "overview.png", title=title)


def draw_all(run: LogRun, out_dir: Path) -> list[Path]:
    """Every figure the log allows (the shared overview first); returns the PNG paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    return [p for f in (fig_overview, *FIGURES) if (p := f(run, out_dir)) is not None]
