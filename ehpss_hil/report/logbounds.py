"""Bounds on what a log makes a report lay out: its sample count and its sample time.

A log comes from a bench, or from anywhere: its ``CycleCount`` may jump or run backwards in file
order (lines out of order, logs of several runs joined) and its timestamps or metadata may give
a sample time no loop runs at (a negative one from timestamps that run backwards). Either would
become arrays of millions of empty samples or metrics on a meaningless time axis; both are one
line (:class:`~ehpss_hil.canlog.LogError`, exit 2) instead.
"""

from __future__ import annotations

from pathlib import Path

from .. import limits
from ..canlog import LogError
from ..canlog.decode import TooLongError
from ..limits import MAX_LOG_SAMPLE_TIME_S, MIN_LOG_SAMPLE_TIME_S


def check_span(log: Path, samples: int, frames: int, name: str) -> None:
    """A :class:`TooLongError` when ``frames`` frames of ``name`` span more samples than a
    report lays out at once (:data:`~ehpss_hil.limits.MAX_LOG_SAMPLES`; a long log is laid out
    in chunks of fewer commands): a ``CycleCount`` that jumps or runs backwards in file order,
    which would otherwise become an array of millions of empty samples."""
    cap = limits.MAX_LOG_SAMPLES
    if samples > cap:
        raise TooLongError(
            f"{log}: too long to report: its {frames} {name} frames span {samples} controller "
            f"samples (at most {cap} at once): its CycleCount jumps (logs of several runs "
            "joined?); cut the log (candump lines stand alone: head -n)"
        )


def check_sample_time(log: Path, ts_s: float, origin: str) -> None:
    """A :class:`LogError` when ``ts_s`` is no sample time a loop can run at (negative: the
    log's timestamps run backwards; beyond the loop rates: a broken clock or metadata)."""
    if not MIN_LOG_SAMPLE_TIME_S <= ts_s <= MAX_LOG_SAMPLE_TIME_S:
        raise LogError(
            f"{log}: sample time {ts_s * 1e3:.4g} ms {origin} is outside "
            f"{MIN_LOG_SAMPLE_TIME_S * 1e3:g}…{MAX_LOG_SAMPLE_TIME_S * 1e3:g} ms (the loop "
            "rates): its timestamps or metadata are broken"
        )
