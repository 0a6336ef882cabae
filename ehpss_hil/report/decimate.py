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
