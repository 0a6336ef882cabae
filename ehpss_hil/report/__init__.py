"""Reports: the docs/design.md §10 metrics (one implementation) and figures."""

from .metrics import RECOVERY_BAND_M, EventMetrics, RunMetrics, compute_metrics

__all__ = ["RECOVERY_BAND_M", "EventMetrics", "RunMetrics", "compute_metrics"]
