"""What a closed :class:`~ehpss_hil.canlog.writer.CandumpLogger` did: :class:`LogSummary`."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class LogSummary:
    """What a closed logger did. ``dropped`` counts queue overflows, lines logged after close and
    lines not written for lack of disk space or a write error, ``dropped_by_reason`` each of them;
    ``discarded`` counts lines in rotated files deleted beyond ``backups``. ``files``: oldest
    first. ``error``: the last write error, if any."""

    path: str
    written: int
    dropped: int
    discarded: int
    files: list[str] = field(default_factory=list)
    error: str | None = None
    dropped_by_reason: dict[str, int] = field(default_factory=dict)

    def __str__(self) -> str:
        s = f"{self.path}: {self.written} frames written, {self.dropped} dropped"
        if self.dropped_by_reason:
            s += " (" + ", ".join(f"{k} {n}" for k, n in self.dropped_by_reason.items()) + ")"
        if self.discarded:
            s += f", {self.discarded} discarded by rotation"
        if self.error:
            s += f" (write error: {self.error})"
        return s
