"""Loop statistics in preallocated numpy ring buffers (no allocation per sample).

Three series per loop: cycle compute time, wake-up lateness and sensor→command latency (s). Each
keeps the newest ``capacity`` samples plus an all-time max and count; the summary gives
p50/p99/p99.9/max.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

SERIES = ("compute_s", "lateness_s", "latency_s")


def peak_rss_bytes() -> int:
    """This process's peak resident set size (bytes): ``VmHWM`` of ``/proc/self/status``, the
    high-water mark of its own address space since its exec. ``getrusage``'s ``ru_maxrss`` is
    only the fallback (no /proc): Linux carries it across exec, so a process started by a large
    one (``ehpss-hil run``/``bench``, through vfork + exec) reports its parent's size there."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


class Ring:
    """A fixed-size ring of float samples (s) with all-time count and max."""

    __slots__ = ("buf", "max", "n")

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        # written now, not lazily: zero pages would become resident one 4 KiB page per 512
        # samples inside the cycle (a page fault each time, and RSS growing for the first
        # ``capacity`` cycles, e.g. 14 MB over 10 minutes at 1 kHz for three rings)
        self.buf = np.full(capacity, 0.0)
        self.n = 0
        self.max = 0.0

    def add(self, value: float) -> None:
        """Record one sample."""
        self.buf[self.n % self.buf.shape[0]] = value
        self.n += 1
        if value > self.max:
            self.max = value

    def values(self) -> np.ndarray:
        """The samples held (newest ``capacity``), unordered."""
        return self.buf[: min(self.n, self.buf.shape[0])]

    def summary(self) -> dict[str, float]:
        """``n``, ``p50``, ``p99``, ``p99_9`` (over the ring) and all-time ``max`` (s)."""
        v = self.values()
        if v.size == 0:
            return {
                "n": 0,
                "p50": float("nan"),
                "p99": float("nan"),
                "p99_9": float("nan"),
                "max": float("nan"),
            }
        p50, p99, p999 = np.percentile(v, [50.0, 99.0, 99.9])
        return {"n": self.n, "p50": float(p50), "p99": float(p99), "p99_9": float(p999), "max": self.max}


class LoopStats:
    """The three rings of one loop plus its overrun count."""

    def __init__(self, capacity: int = 600_000) -> None:
        self.compute = Ring(capacity)
        self.lateness = Ring(capacity)
        self.latency = Ring(capacity)
        self.overruns = 0
        self.skipped = 0

    def summary(self) -> dict[str, Any]:
        """A JSON-able dict: one sub-dict per series (s), overruns, skipped periods."""
        return {
            "compute_s": self.compute.summary(),
            "lateness_s": self.lateness.summary(),
            "latency_s": self.latency.summary(),
            "overruns": self.overruns,
            "skipped": self.skipped,
        }

    def text(self) -> str:
        """Human-readable summary, one line per series in µs."""
        s = self.summary()
        lines = []
        for key in SERIES:
            d = s[key]
            lines.append(
                f"{key[:-2]:9s} n={d['n']:<8d} p50={d['p50'] * 1e6:8.1f} µs "
                f"p99={d['p99'] * 1e6:8.1f} µs p99.9={d['p99_9'] * 1e6:8.1f} µs "
                f"max={d['max'] * 1e6:8.1f} µs"
            )
        lines.append(f"overruns={self.overruns} skipped_periods={self.skipped}")
        return "\n".join(lines)


def rejects_text(summary: dict[str, Any]) -> str:
    """``0`` or ``5 (empty 1, not msgpack 4)``: a summary's ``rejected_datagrams`` in words."""
    r = summary.get("rejected_datagrams") or {}
    reasons = ", ".join(f"{k} {n}" for k, n in (r.get("by_reason") or {}).items())
    return f"{r.get('total', 0)}" + (f" ({reasons})" if reasons else "")


def publish_summary(
    fmt: Callable[[dict[str, Any]], str], summary: dict[str, Any], json_path: Path | None
) -> None:
    """A process's exit summary: ``fmt(summary)`` on stdout, and the whole dict as JSON to
    ``json_path`` when given (what ``run`` and the benches read back; written whole or not at
    all: a full or read-only folder gives one warning line, not an error, as control is over)."""
    print(fmt(summary), flush=True)
    if json_path is None:
        return
    tmp = json_path.with_name(json_path.name + ".tmp")
    try:
        tmp.write_text(json.dumps(summary, indent=1))
        os.replace(tmp, json_path)
    except OSError as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        log.warning("exit summary %s not written: %s", json_path, exc.strerror or exc)
