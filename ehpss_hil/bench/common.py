"""Shared helpers for benchmarks: the PASS/FAIL scorecard behind every bench's exit code,
percentiles and JSON output."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


@dataclass
class Scorecard:
    """Every PASS/FAIL a benchmark prints, kept so that its exit code follows them: each
    bench's ``run`` returns its scorecard and ``ehpss-hil bench`` exits with
    :meth:`exit_code` (1 when any target failed) after printing :meth:`line`."""

    passed: int = 0
    #: what failed, one entry per FAIL printed
    failed: list[str] = field(default_factory=list)

    def mark(self, ok: bool | None, what: str) -> str:
        """``PASS``/``FAIL`` for the table (``""`` when ``ok`` is None: information, no target);
        a FAIL is remembered as ``what``."""
        if ok is None:
            return ""
        if ok:
            self.passed += 1
            return "PASS"
        self.failed.append(what)
        return "FAIL"

    @property
    def ok(self) -> bool:
        """No target failed."""
        return not self.failed

    def exit_code(self) -> int:
        """0 when no target failed, else 1."""
        return 0 if self.ok else 1

    def line(self, name: str) -> str:
        """``bench NAME: 12 targets PASS`` or ``… 2 of 14 targets FAIL: a; b``."""
        total = self.passed + len(self.failed)
        if self.ok:
            return (
                f"bench {name}: {total} target(s) PASS"
                if total
                else f"bench {name}: figures only, no targets"
            )
        return f"bench {name}: {len(self.failed)} of {total} target(s) FAIL: {'; '.join(self.failed)}"


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
