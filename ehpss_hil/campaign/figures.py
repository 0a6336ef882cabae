"""Campaign figures (matplotlib, the optional ``plot`` extra): coverage maps of mmac/oracle RMS and
the distributions of recovery time and model switches.

* ``coverage-loe-drift.png``: median mmac/oracle RMS over LOE (1 − k_LOE) × drift |1 − k_DFT|,
  from the runs whose faults are LOE and/or drift only (an absent fault counts as 0);
* ``coverage-onset.png``: per fault kind, median mmac/oracle RMS over that fault's onset (s) ×
  magnitude (the kind's unit), from every run that has it;
* ``distributions.png``: recovery time (the longest over a run's events, finite ones) and model
  switches per run, per mode.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .spec import FAULT_KINDS

#: the files :func:`write_figures` may write
FIGURE_NAMES = ("coverage-loe-drift.png", "coverage-onset.png", "distributions.png")
#: bins per axis of a coverage map
MAP_BINS = 8
#: colour range of the mmac/oracle RMS ratio (log scale, 1 in the middle: blue = mmac better
#: than the oracle, red = worse)
RATIO_RANGE = (0.01, 100.0)
#: y-axis label per fault kind (what its magnitude is)
MAGNITUDE_LABEL = {
    "loe": "k_LOE",
    "kq": "k_Q",
    "drift": "k_DFT",
    "sensor_failure": "k_DFT (fixed 0)",
    "bias": "bias (m)",
    "stuck": "(no magnitude)",
    "frame_loss": "loss probability",
}


def _binned_median(x: np.ndarray, y: np.ndarray, v: np.ndarray, bins: int) -> tuple[Any, Any, Any]:
    """Median of ``v`` per (x, y) bin (NaN: empty), with the bin edges."""
    xe = np.linspace(x.min(), x.max() if x.max() > x.min() else x.min() + 1.0, bins + 1)
    ye = np.linspace(y.min(), y.max() if y.max() > y.min() else y.min() + 1.0, bins + 1)
    ix = np.clip(np.digitize(x, xe) - 1, 0, bins - 1)
    iy = np.clip(np.digitize(y, ye) - 1, 0, bins - 1)
    grid = np.full((bins, bins), np.nan)
    for i in range(bins):
        for j in range(bins):
            sel = (ix == i) & (iy == j)
            if sel.any():
                grid[j, i] = np.median(v[sel])
    return xe, ye, grid


def _col(rows: Sequence[dict[str, Any]], key: str) -> np.ndarray:
    return np.asarray([r[key] for r in rows], dtype=float)


def _ratio(rows: Sequence[dict[str, Any]]) -> np.ndarray:
    return _col(rows, "mmac.rms_error_m") / np.maximum(_col(rows, "oracle.rms_error_m"), 1e-12)


def _map(ax: Any, x: np.ndarray, y: np.ndarray, v: np.ndarray) -> Any:
    from matplotlib.colors import LogNorm

    xe, ye, grid = _binned_median(x, y, np.clip(v, *RATIO_RANGE), MAP_BINS)
    return ax.pcolormesh(xe, ye, grid, norm=LogNorm(*RATIO_RANGE), cmap="RdBu_r", shading="flat")


def coverage_loe_drift(rows: Sequence[dict[str, Any]], path: Path) -> Path | None:
    """The LOE × drift map (None: no run with only those faults)."""
    import matplotlib.pyplot as plt

    sel = [r for r in rows if r["fault_class"] in ("loe", "drift", "drift+loe")]
    if not sel:
        return None
    loe = 1.0 - np.nan_to_num(_col(sel, "loe.magnitude"), nan=1.0)
    drift = np.abs(1.0 - np.nan_to_num(_col(sel, "drift.magnitude"), nan=1.0))
    fig, ax = plt.subplots(figsize=(6.4, 5.0), layout="constrained")
    mesh = _map(ax, loe, drift, _ratio(sel))
    ax.scatter(loe, drift, s=6, c="white", edgecolors="black", linewidths=0.3)
    ax.set_xlabel("LOE 1 − k_LOE")
    ax.set_ylabel("drift |1 − k_DFT|")
    ax.set_title(f"mmac / oracle RMS (median per cell), {len(sel)} runs")
    fig.colorbar(mesh, ax=ax, label="mmac / oracle RMS")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def coverage_onset(rows: Sequence[dict[str, Any]], path: Path) -> Path | None:
    """Per kind: onset × magnitude maps (None: no fault in any run)."""
    import matplotlib.pyplot as plt

    kinds = [k for k in FAULT_KINDS if any(not np.isnan(r[f"{k}.onset_s"]) for r in rows)]
    if not kinds:
        return None
    ncol = min(4, len(kinds))
    nrow = -(-len(kinds) // ncol)
    fig, axes = plt.subplots(
        nrow, ncol, figsize=(3.6 * ncol, 3.0 * nrow), squeeze=False, layout="constrained"
    )
    mesh: Any = None
    for ax, kind in zip(axes.flat, kinds, strict=False):
        sel = [r for r in rows if not np.isnan(r[f"{kind}.onset_s"])]
        x, y = _col(sel, f"{kind}.onset_s"), _col(sel, f"{kind}.magnitude")
        mesh = _map(ax, x, y, _ratio(sel))
        ax.scatter(x, y, s=4, c="white", edgecolors="black", linewidths=0.2)
        ax.set_title(f"{kind} ({len(sel)} runs)", fontsize=9)
        ax.set_xlabel("onset (s)", fontsize=8)
        ax.set_ylabel(MAGNITUDE_LABEL[kind], fontsize=8)
    for ax in list(axes.flat)[len(kinds) :]:
        ax.set_visible(False)
    fig.suptitle("mmac / oracle RMS over fault onset × magnitude (median per cell)")
    fig.colorbar(mesh, ax=axes, label="mmac / oracle RMS")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def distributions(rows: Sequence[dict[str, Any]], modes: Sequence[str], path: Path) -> Path:
    """Histograms of recovery time (finite) and switches per run, per mode."""
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
    top = max(int(_col(rows, f"{m}.switches").max()) for m in modes)
    edges = np.arange(top + 2) - 0.5  # one bin per whole number of switches
    for m in modes:
        rec = _col(rows, f"{m}.recovery_s")
        never = int(np.count_nonzero(np.isinf(rec)))
        a1.hist(rec[np.isfinite(rec)], bins=30, histtype="step", label=f"{m} ({never} never)")
        a2.hist(_col(rows, f"{m}.switches"), bins=edges, histtype="step", label=m)
    a1.set_xlabel("longest recovery per run (s)")
    a1.set_ylabel("runs")
    a1.legend(fontsize=8)
    a2.set_xlabel("model switches per run")
    a2.set_ylabel("runs")
    a2.legend(fontsize=8)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def write_figures(rows: Sequence[dict[str, Any]], modes: Sequence[str], out: Path) -> list[Path]:
    """Every figure into ``out`` (none without matplotlib or rows)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
    except ImportError:
        return []
    if not rows:
        return []
    loe_drift, onset, dist = (out / n for n in FIGURE_NAMES)
    made = [
        coverage_loe_drift(rows, loe_drift),
        coverage_onset(rows, onset),
        distributions(rows, modes, dist),
    ]
    return [p for p in made if p is not None]
