"""Campaign figures (matplotlib, the optional ``plot`` extra): coverage maps of mmac/oracle RMS and
the distributions of recovery time and model switches.

* ``coverage-loe-drift.png``: median mmac/oracle RMS over LOE (1 − k_LOE) × drift |1 − k_DFT|,
  from the runs whose faults are LOE and/or drift only (an absent fault counts as 0);
* ``coverage-onset.png``: per fault kind, median mmac/oracle RMS over that fault's onset (s) ×
  magnitude (the kind's unit), from every run that has it; a kind without a magnitude (stuck,
  sensor failure) over its onset alone (one row of cells);
* ``distributions.png``: recovery time (the longest over a run's events, finite ones) and model
  switches per run, per mode.

The cells of a map follow the data: about :data:`RUNS_PER_CELL` runs a cell on average (bins per
axis from the number of runs, 1 … :data:`MAX_BINS`), so 14 runs make a 2 × 2 map, not a 8 × 8
one of empty cells and single runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .spec import FAULT_KINDS, MAGNITUDE_BOUNDS

#: the files :func:`write_figures` may write
FIGURE_NAMES = ("coverage-loe-drift.png", "coverage-onset.png", "distributions.png")
#: runs a coverage-map cell holds on average (a median of fewer says little)
RUNS_PER_CELL = 4
#: most bins per axis of a coverage map
MAX_BINS = 12
#: colour range of the mmac/oracle RMS ratio (log scale, 1 in the middle: blue = mmac better
#: than the oracle, red = worse)
RATIO_RANGE = (0.01, 100.0)
#: colour of a map cell that holds no run (matplotlib grey level)
EMPTY_CELL_COLOR = "0.8"
#: y-axis label per fault kind with a magnitude (:data:`~.spec.MAGNITUDE_BOUNDS`: what it is)
MAGNITUDE_LABEL = {
    "loe": "k_LOE",
    "kq": "k_Q",
    "drift": "k_DFT",
    "bias": "bias (m)",
    "frame_loss": "loss probability",
}


def map_bins(runs: int, axes: int = 2) -> int:
    """Bins per axis for ``runs`` runs on ``axes`` axes: about :data:`RUNS_PER_CELL` a cell."""
    return int(np.clip(round((runs / RUNS_PER_CELL) ** (1.0 / axes)), 1, MAX_BINS))


def _edges(x: np.ndarray, bins: int) -> np.ndarray:
    hi = x.max() if x.max() > x.min() else x.min() + 1.0
    return np.linspace(x.min(), hi, bins + 1)


def binned_median(x: np.ndarray, y: np.ndarray | None, v: np.ndarray) -> tuple[Any, Any, Any]:
    """Median of ``v`` per (x, y) cell (NaN: empty) and the cell edges, bins from the number of
    runs; ``y`` None: one row of cells over ``x`` (edges 0, 1 on y)."""
    if y is None:
        xe, ye = _edges(x, map_bins(len(x), 1)), np.array([0.0, 1.0])
        iy = np.zeros(len(x), dtype=int)
    else:
        bins = map_bins(len(x))
        xe, ye = _edges(x, bins), _edges(y, bins)
        iy = np.clip(np.digitize(y, ye) - 1, 0, len(ye) - 2)
    ix = np.clip(np.digitize(x, xe) - 1, 0, len(xe) - 2)
    grid = np.full((len(ye) - 1, len(xe) - 1), np.nan)
    for j, i in set(zip(iy.tolist(), ix.tolist(), strict=True)):
        grid[j, i] = np.median(v[(ix == i) & (iy == j)])
    return xe, ye, grid


def _col(rows: Sequence[dict[str, Any]], key: str) -> np.ndarray:
    return np.asarray([r[key] for r in rows], dtype=float)


def _ratio(rows: Sequence[dict[str, Any]]) -> np.ndarray:
    return _col(rows, "mmac.rms_error_m") / np.maximum(_col(rows, "oracle.rms_error_m"), 1e-12)


def _map(ax: Any, x: np.ndarray, y: np.ndarray | None, v: np.ndarray) -> Any:
    from matplotlib.colors import LogNorm

    xe, ye, grid = binned_median(x, y, np.clip(v, *RATIO_RANGE))
    ax.set_facecolor(EMPTY_CELL_COLOR)  # a cell without runs, not white (white is a ratio of 1)
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
    ax.set_title(f"mmac / oracle RMS (median per cell; grey: no run), {len(sel)} runs")
    fig.colorbar(mesh, ax=ax, label="mmac / oracle RMS")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def coverage_onset(rows: Sequence[dict[str, Any]], path: Path) -> Path | None:
    """Per kind: onset × magnitude maps, written to ``path`` (None: no fault in any run)."""
    import matplotlib.pyplot as plt

    fig = onset_figure(rows)
    if fig is None:
        return None
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def onset_figure(rows: Sequence[dict[str, Any]]) -> Any:
    """The figure of :func:`coverage_onset` (a matplotlib Figure; None: no fault in any run)."""
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
        x = _col(sel, f"{kind}.onset_s")
        y = _col(sel, f"{kind}.magnitude") if kind in MAGNITUDE_BOUNDS else None
        mesh = _map(ax, x, y, _ratio(sel))
        ax.scatter(
            x,
            y if y is not None else np.full(len(x), 0.5),
            s=4,
            c="white",
            edgecolors="black",
            linewidths=0.2,
        )
        ax.set_title(f"{kind} ({len(sel)} runs)", fontsize=9)
        ax.set_xlabel("onset (s)", fontsize=8)
        if y is not None:
            ax.set_ylabel(MAGNITUDE_LABEL[kind], fontsize=8)
        else:  # no magnitude: the onset is the one axis
            ax.set_yticks([])
    for ax in list(axes.flat)[len(kinds) :]:
        ax.set_visible(False)
    fig.suptitle("mmac / oracle RMS over fault onset × magnitude (median per cell; grey: no run)")
    fig.colorbar(mesh, ax=axes, label="mmac / oracle RMS")
    return fig


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
