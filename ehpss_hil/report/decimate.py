"""A long run thinned for its figures: at most :data:`MAX_PLOT_SAMPLES` samples drawn.

A figure cannot show more samples than it has pixels, and matplotlib keeps every point it is
given (hundreds of MB for an hour at 1 kHz). The metrics are computed on every sample; only the
figures of a run longer than :data:`MAX_PLOT_SAMPLES` are drawn from one sample per bucket of
``ceil(n / MAX_PLOT_SAMPLES)`` consecutive samples: the one with the largest tracking error
``|x_true − y_m|`` in the bucket (so every error peak is drawn at its height), the first one where
no error is known.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from .logdata import LogRun
from .result import SimResult

#: most samples a figure draws (a 12-inch figure at 150 dpi is 1800 pixels wide)
MAX_PLOT_SAMPLES = 20_000


def bucket_rows(err: np.ndarray, step: int) -> np.ndarray:
    """Row index of the largest ``|err|`` in each bucket of ``step`` rows (NaN counts as
    smallest; a bucket of NaN gives its first row)."""
    n = len(err)
    buckets = math.ceil(n / step)
    pad = np.full(buckets * step, -np.inf)
    a = np.abs(err)
    pad[:n] = np.where(np.isfinite(a), a, -np.inf)
    return np.minimum(np.arange(buckets) * step + np.argmax(pad.reshape(buckets, step), axis=1), n - 1)


def thinned(run: LogRun, max_samples: int = MAX_PLOT_SAMPLES) -> LogRun:
    """``run`` itself when it has at most ``max_samples`` samples, else a copy whose per-sample
    arrays keep one row per bucket (module docstring); frames and metadata are shared."""
    r = run.result
    n = len(r.t_s)
    if n <= max_samples:
        return run
    rows = bucket_rows(r.x_true_m - r.y_m_m, math.ceil(n / max_samples))
    changes = {
        f.name: getattr(r, f.name)[rows]
        for f in dataclasses.fields(SimResult)
        if isinstance(getattr(r, f.name), np.ndarray) and len(getattr(r, f.name)) == n
    }
    cmd = run.commanded_current_a[rows] if len(run.commanded_current_a) == n else run.commanded_current_a
    return dataclasses.replace(run, result=dataclasses.replace(r, **changes), commanded_current_a=cmd)


#: pixel columns a :class:`MinMaxDecimator` view is drawn for (a 10.5-inch figure at 110 dpi
#: is 1155 pixels wide): two rows each. More rows add nothing a figure shows, but cost memory
#: while it is drawn (a dense zigzag of 20 000 rows took Agg ≈ 40 MB more per figure)
MAX_PIXEL_COLUMNS = 2000

#: the fields a :class:`MinMaxDecimator` takes at the rows of the smallest and largest tracking
#: error of a bucket (so the error drawn, x − y_m, keeps every peak at its height and sign)
_PICKED = ("t_s", "x_d_m", "y_m_m", "x_true_m")
#: the per-sample fields of which it keeps each bucket's smallest and largest value
_RANGED = (
    "y_s_m",
    "spool_m",
    "current_a",
    "active_spool",
    "active_position",
    "k_loe_hat",
    "k_dft_hat",
    "index",
    "true_k_loe",
    "true_k_q",
    "true_k_dft",
    "fresh",
    "stuck",
    "commanded_a",
)


class MinMaxDecimator:
    """A run of any length, fed in parts, thinned for its figures with bounded memory: buckets
    of consecutive samples, two rows each — x_d, y_m and x at the samples of the bucket's
    smallest and largest error ``x − y_m``, every other signal its smallest and largest value
    (NaN ignored), so a spike of any signal survives. The bucket length doubles (neighbours
    merged) whenever more than ``max_samples / 2`` buckets are held."""

    def __init__(self, max_samples: int = 2 * MAX_PIXEL_COLUMNS) -> None:
        self.max_buckets = max(1, max_samples // 2)
        self.size = 1
        self.held: dict[str, np.ndarray] = {}  # name → (buckets, 2[, 16]) values
        self.pending: dict[str, np.ndarray] = {}  # raw rows not yet a whole bucket
        self.n = 0

    def add(self, rows: dict[str, np.ndarray]) -> None:
        """Append consecutive samples: every name of ``_PICKED`` and ``_RANGED`` (``stuck`` may
        be empty: not recorded)."""
        m = len(rows["t_s"])
        self.n += m
        rows = {k: (v if len(v) == m else np.zeros(m, bool)) for k, v in rows.items()}
        raw = {k: np.concatenate((self.pending[k], v)) if k in self.pending else v for k, v in rows.items()}
        full = len(raw["t_s"]) // self.size * self.size
        self.pending = {k: v[full:] for k, v in raw.items()}
        if full:
            self._append(self._reduce({k: v[:full] for k, v in raw.items()}, self.size))
        while len(self.held["t_s"]) > self.max_buckets:
            self._merge()

    @staticmethod
    def _reduce(raw: dict[str, np.ndarray], size: int) -> dict[str, np.ndarray]:
        """Buckets of ``size`` raw rows → (buckets, 2) picked rows and (min, max) ranges."""
        nb = len(raw["t_s"]) // size
        err = (raw["x_true_m"] - raw["y_m_m"]).reshape(nb, size)
        cand = {k: raw[k].astype(float).reshape(nb, size, *raw[k].shape[1:]) for k in raw}
        cand["err"] = err
        return MinMaxDecimator._pick(cand)

    @staticmethod
    def _pick(cand: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """From candidates (buckets, c[, 16]) the two rows of the extreme errors (in time
        order) and the (min, max) of the ranged fields."""
        err = cand["err"]
        lo = np.argmin(np.where(np.isnan(err), np.inf, err), axis=1)
        hi = np.argmax(np.where(np.isnan(err), -np.inf, err), axis=1)
        rows = np.sort(np.stack((lo, hi), axis=1), axis=1)
        out = {k: np.take_along_axis(cand[k], rows, axis=1) for k in (*_PICKED, "err")}
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            for k in _RANGED:
                out[k] = np.stack((np.nanmin(cand[k], axis=1), np.nanmax(cand[k], axis=1)), axis=1)
        return out

    def _append(self, part: dict[str, np.ndarray]) -> None:
        self.held = {k: np.concatenate((self.held[k], v)) if k in self.held else v for k, v in part.items()}

    def _merge(self) -> None:
        """Neighbouring buckets merged in pairs (an odd last one stays); the length doubles."""
        nb = len(self.held["t_s"]) // 2 * 2
        pairs = {k: v[:nb].reshape(nb // 2, 4, *v.shape[2:]) for k, v in self.held.items()}
        merged = self._pick(pairs)
        self.held = {k: np.concatenate((merged[k], v[nb:])) for k, v in self.held.items()}
        self.size *= 2

    def rows(self) -> dict[str, np.ndarray]:
        """The thinned samples (two per bucket, the pending tail as it is), flattened."""
        parts = [{k: v.reshape(-1, *v.shape[2:]) for k, v in self.held.items()}] if self.held else []
        if self.pending and len(self.pending["t_s"]):
            parts.append({k: v.astype(float) for k, v in self.pending.items()})
        keys = (*_PICKED, *_RANGED)
        return {k: np.concatenate([p[k] for p in parts]) if parts else np.zeros(0) for k in keys}
