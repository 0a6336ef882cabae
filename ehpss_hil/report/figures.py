"""Figures like the paper's Figs 4–7: response, control input, active models, estimates.

matplotlib is optional (``pip install ehpss-hil[plot]``); it is imported only when a figure is made.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import EhpssError
from .result import SimResult


def _pyplot() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise EhpssError("plotting needs matplotlib: pip install 'ehpss-hil[plot]'") from exc
    return plt


def plot_run(r: SimResult, path: str | Path, title: str | None = None) -> Path:
    """Write a 5-panel PNG of one run: (a) x, y_m, x_d; (b) e = x − y_m; (c) coil current;
    (d) active model slot per channel; (e) k̂_LOE, k̂_DFT against the true values."""
    plt = _pyplot()
    t = r.t_s
    fig, ax = plt.subplots(5, 1, figsize=(9, 12), sharex=True)
    ax[0].plot(t, r.x_d_m * 1e3, "k:", lw=1, label="x_d")
    ax[0].plot(t, r.y_m_m * 1e3, "b-", lw=1, label="y_m (reference model)")
    ax[0].plot(t, r.x_true_m * 1e3, "r--", lw=1, label="x (true)")
    ax[0].set_ylabel("position (mm)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].plot(t, r.error_m * 1e6, "r-", lw=0.8)
    ax[1].set_ylabel("x − y_m (µm)")
    ax[2].plot(t, r.current_a * 1e3, "g-", lw=0.8)
    ax[2].set_ylabel("coil current (mA)")
    ax[3].step(t, r.active_spool, where="post", label="spool / joint")
    if not np.array_equal(r.active_spool, r.active_position):
        ax[3].step(t, r.active_position, where="post", label="position")
    ax[3].set_ylabel("active model slot")
    ax[3].legend(loc="upper right", fontsize=8)
    ax[4].plot(t, r.true_k_loe * r.true_k_q, "k-", lw=1, label="k_LOE·k_Q (true)")
    ax[4].plot(t, r.true_k_dft, "k--", lw=1, label="k_DFT (true)")
    ax[4].plot(t, r.k_loe_hat, "b-", lw=0.8, label="k̂_LOE")
    ax[4].plot(t, r.k_dft_hat, "r-", lw=0.8, label="k̂_DFT")
    ax[4].set_ylabel("fault gains")
    ax[4].set_xlabel("t (s)")
    ax[4].legend(loc="upper right", fontsize=8)
    fb = r.fallback
    for a in ax:
        a.grid(True, alpha=0.3)
        for te in r.event_times_s:
            a.axvline(te, color="0.6", lw=0.6)
        if len(fb) == len(t) and fb.any():  # the do-no-harm monitor's nominal fallback
            a.fill_between(
                t,
                0,
                1,
                where=fb,
                transform=a.get_xaxis_transform(),
                color="orange",
                alpha=0.25,
                lw=0,
                label="nominal fallback" if a is ax[3] else None,
            )
    if len(fb) == len(t) and fb.any():
        ax[3].legend(loc="upper right", fontsize=8)
    fig.suptitle(title or f"{r.scenario} — {r.controller}")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
