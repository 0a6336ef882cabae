"""Figures like the paper's Figs 4–7 for one run or several overlaid (NRC vs MMAC): response,
tracking error, control input, active models, estimates.

Every fault event is a dashed line named above the top panel ("LOE 50 %", "drift 0.8"); the
intervals a run spent in FAULT or on its nominal fallback are shaded in their reason's colour
(:mod:`ehpss_hil.reasons`) and named in the legend; modes without an estimator (NRC) draw no
k̂ or active-model trace; samples
the metrics did not count are drawn as gaps over a grey band, never as if they counted. Legends
sit outside the axes, never over data. matplotlib is optional (``pip install ehpss-hil[plot]``);
it is imported only when a figure is made.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..extras import require
from ..reasons import reason_color
from .annotate import Interval, event_labels, fallback_intervals, runs_of
from .result import SimResult

#: line colour per controller mode (the same mode keeps its colour in every figure)
MODE_COLORS = {"nrc": "C3", "smac": "C2", "mmac-paper": "C4", "mmac": "C0", "oracle": "C5"}
#: modes whose controller has no estimator: no k̂ and no active-model trace is drawn for them
#: (NRC reports the nominal values, which would read as an estimate that never moves)
MODES_WITHOUT_ESTIMATOR = frozenset({"nrc"})


def has_estimator(mode: str) -> bool:
    """Whether a run of controller ``mode`` has estimates (k̂, an active model) to draw."""
    return mode not in MODES_WITHOUT_ESTIMATOR


@dataclass
class RunView:
    """One run as a figure draws it: the result, its line label, the events in words, the FAULT
    and fallback intervals, and which samples the metrics counted (empty: all)."""

    result: SimResult
    label: str = ""
    events: list[tuple[float, str]] = field(default_factory=list)
    intervals: list[Interval] = field(default_factory=list)
    counted: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    @classmethod
    def of(cls, r: SimResult, scenario_events: tuple[Any, ...] = ()) -> RunView:
        """A lockstep result: events from the scenario (or the true gains), fallback intervals."""
        return cls(r, r.controller, event_labels(r, scenario_events), fallback_intervals(r))

    @property
    def color(self) -> str:
        return MODE_COLORS.get(self.result.controller, "C1")


def _pyplot() -> Any:
    require("plot", "plotting")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _masked(v: np.ndarray, counted: np.ndarray) -> np.ndarray:
    """``v`` with the samples the metrics did not count as gaps (NaN)."""
    if len(counted) != len(v):
        return v
    return np.where(counted, v, np.nan)


def estimating(v: RunView) -> np.ndarray:
    """Per sample, whether the controller had an estimate in use: False inside its FAULT
    intervals (it resets its estimators there; the reset values would read as a jump)."""
    t = v.result.t_s
    ok = np.ones(len(t), bool)
    for iv in v.intervals:
        if iv.kind == "FAULT":
            ok &= (t < iv.t0_s) | (t >= iv.t1_s)
    return ok


def mark_events(axes: list[Any], events: list[tuple[float, str]]) -> None:
    """Dashed lines at the events on every axis; their names above the top one (not over data)."""
    for ax in axes:
        for t, _ in events:
            ax.axvline(t, color="0.35", ls="--", lw=0.8)
    for i, (t, words) in enumerate(events):
        axes[0].annotate(
            words,
            xy=(t, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(2, 2 + 10 * (i % 2)),
            textcoords="offset points",
            fontsize=8,
            color="0.15",
            va="bottom",
        )


def shade(axes: list[Any], views: list[RunView], several: bool) -> None:
    """Shade each view's FAULT/fallback intervals in their reason's colour (labelled once in
    the legend of the last axis, with the mode when several runs are drawn) and the samples its
    metrics left out."""
    labelled: set[str] = set()
    for v in views:
        r = v.result
        for iv in v.intervals:
            label = f"{r.controller} {iv.label}" if several else iv.label
            for ax in axes:
                ax.axvspan(
                    iv.t0_s,
                    iv.t1_s,
                    color=reason_color(iv.kind, iv.reason),
                    alpha=0.22,
                    lw=0,
                    label=label if ax is axes[-1] and label not in labelled else None,
                )
            labelled.add(label)
        if len(v.counted) == len(r.t_s) and not v.counted.all():
            label = "not in the metrics"
            for i0, i1 in runs_of(~v.counted):
                t1 = r.t_s[i1] if i1 < len(r.t_s) else r.t_s[-1] + r.ts_s
                for ax in axes:
                    ax.axvspan(
                        r.t_s[i0],
                        t1,
                        color="0.6",
                        alpha=0.25,
                        hatch="//",
                        lw=0,
                        label=label if ax is axes[-1] and label not in labelled else None,
                    )
                labelled.add(label)


def _outside_legend(ax: Any) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)


def draw_runs(views: list[RunView], title: str | None = None) -> Any:
    """The matplotlib figure of :func:`plot_runs` (the caller saves and closes it): (a) x of
    each run with x_d and y_m; (b) e = x − y_m; (c) coil current; (d) active model slot per
    channel; (e) k̂_LOE, k̂_DFT with the true gains, gaps in FAULT (panels (d), (e) without the
    runs of a mode that has no estimator). Several runs share the reference and the events (the
    first run's)."""
    plt = _pyplot()
    several = len(views) > 1
    first = views[0].result
    fig, ax = plt.subplots(5, 1, figsize=(11, 12.5), sharex=True, layout="constrained")
    ax[0].plot(first.t_s, first.x_d_m * 1e3, color="0.55", ls=":", lw=1, label="x_d")
    ax[0].plot(first.t_s, first.y_m_m * 1e3, "k-", lw=1, label="y_m (reference model)")
    for v in views:
        r, c = v.result, v.color
        name = f" {v.label}" if several else ""
        ax[0].plot(r.t_s, _masked(r.x_true_m, v.counted) * 1e3, color=c, ls="--", lw=1, label=f"x{name}")
        ax[1].plot(r.t_s, _masked(r.error_m, v.counted) * 1e6, color=c, lw=0.8, label=f"e{name}")
        ax[2].plot(r.t_s, r.current_a * 1e3, color=c, lw=0.8, label=f"i{name}")
        if not has_estimator(r.controller):
            continue
        if np.any(r.active_spool >= 0) or np.any(r.active_position >= 0):
            ax[3].step(r.t_s, r.active_spool, where="post", color=c, label=f"spool / joint{name}")
            if not np.array_equal(r.active_spool, r.active_position):
                ax[3].step(r.t_s, r.active_position, where="post", color=c, ls="--", label=f"position{name}")
        est = estimating(v)
        ax[4].plot(r.t_s, np.where(est, r.k_loe_hat, np.nan), color=c, lw=0.9, label=f"k̂_LOE{name}")
        ax[4].plot(r.t_s, np.where(est, r.k_dft_hat, np.nan), color=c, lw=0.9, ls="-.", label=f"k̂_DFT{name}")
    ax[4].plot(
        first.t_s, first.true_k_loe * first.true_k_q, "k-", lw=1.2, alpha=0.6, label="k_LOE·k_Q (true)"
    )
    ax[4].plot(first.t_s, first.true_k_dft, "k--", lw=1.2, alpha=0.6, label="k_DFT (true)")
    for a, ylabel in zip(
        ax,
        ("position (mm)", "e = x − y_m (µm)", "coil current (mA)", "active model slot", "fault gains"),
        strict=True,
    ):
        a.set_ylabel(ylabel)
        a.grid(True, alpha=0.3)
    ax[4].set_xlabel("t (s)")
    mark_events(list(ax), views[0].events)
    shade(list(ax), views, several)
    for a in ax:
        _outside_legend(a)
    modes = " vs ".join(v.label or v.result.controller for v in views)
    fig.suptitle(title or f"{first.scenario} — {modes}")
    return fig


def plot_runs(views: list[RunView], path: str | Path, title: str | None = None) -> Path:
    """Write the 5-panel PNG of :func:`draw_runs` of one or several runs of one scenario."""
    plt = _pyplot()
    fig = draw_runs(views, title)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_run(r: SimResult, path: str | Path, title: str | None = None) -> Path:
    """:func:`plot_runs` of one lockstep result (events in words from its true gains)."""
    return plot_runs([RunView.of(r)], path, title)
