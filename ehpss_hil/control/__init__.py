"""Control laws: PI (eq 39), predictors, NLMS estimators, model banks, supervisor, compensation.

Pure code, no I/O. Every controller implements :class:`~ehpss_hil.control.base.Controller`.
"""
