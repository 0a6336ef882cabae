"""Shared helpers for benchmarks: percentiles and JSON output."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np


def percentiles_us(samples_s: np.ndarray) -> dict[str, float]:
    """p50/p99/p99.9/max of durations given in seconds, returned in microseconds."""
    if len(samples_s) == 0:
        return {
            "p50_us": float("nan"),
            "p99_us": float("nan"),
            "p999_us": float("nan"),
            "max_us": float("nan"),
        }
    us = np.asarray(samples_s) * 1e6
    p50, p99, p999 = np.percentile(us, [50, 99, 99.9])
    return {"p50_us": float(p50), "p99_us": float(p99), "p999_us": float(p999), "max_us": float(us.max())}


def write_json(path: str | Path | None, payload: Any) -> None:
    """Write ``payload`` as indented JSON when a path is given."""
    if path:
        Path(path).write_text(json.dumps(payload, indent=2, allow_nan=False, default=str) + "\n")


def finite_json(payload: Any) -> Any:
    """``payload`` with NaN/±∞ floats replaced by None (strict JSON, as :func:`write_json`
    writes; e.g. a percentile of an empty series)."""
    if isinstance(payload, float):
        return payload if math.isfinite(payload) else None
    if isinstance(payload, dict):
        return {k: finite_json(v) for k, v in payload.items()}
    if isinstance(payload, list | tuple):
        return [finite_json(v) for v in payload]
    return payload
