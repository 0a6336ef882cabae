"""A position reading that jumps is the sensor's doing, never the flow gain's.

Only ``k_DFT·k_Q`` is identifiable from the position and the spool; the load-pressure test
(:mod:`.pressure`) splits it, but needs tens of milliseconds of evidence. An abrupt sensor
fault gives itself away sooner: the piston position is the integral of the flow, so whatever
the flow gain does, the piston moves over one sample by between nothing and the full flow the
spool commands, ``Δx ∈ [0, K_c·∫y_v]`` over the sample (the integral of the measured spool at the
nominal flow gain; a flow-gain *loss* k_Q ≤ 1 assumed). A sensor whose gain steps from k to k'
jumps by ``(k' − k)·x`` in one sample instead.

:class:`LevelJump` compares each contiguous sample's position increment ``Δy_s`` with that band
scaled by the sensor's present increment gain θ_prod (:meth:`.Increments.product`):
the distance of ``Δy_s`` outside ``θ_prod·[0, K_c·∫y_v]``, in units of the increment noise σ̂ (an
exponentially weighted RMS of ``Δy_s − θ_prod·K_c·∫y_v`` over the samples that did not jump), is the
statistic; above ``jump_sigmas`` the reading jumped. A jump at a small position (a gain step
near x = 0) stays inside the noise and goes unseen; so does the error it would cause. A jump
also measures the sensor's gain change, :attr:`LevelJump.ratio` = k'/k ≈ (y_s − θ_prod·K_c·∫y_v)
/ y_s,before: a position model that changes by that ratio is the sensor's.
"""

from __future__ import annotations

import math

from ..tuning import ControlTuning


class LevelJump:
    """Per contiguous sample: did the position reading jump? (:meth:`update`)."""

    __slots__ = (
        "_gain",
        "_hold",
        "_jump2",
        "_min_n",
        "_n",
        "_n_avg",
        "_ratio2",
        "_settle",
        "_var",
        "_w",
        "_x",
        "_y",
        "ratio",
    )

    def __init__(self, settle_samples: int, tuning: ControlTuning | None = None) -> None:
        """``settle_samples``: after a jump, the increment gain passed in is not used for this
        many samples (θ_prod's increments span the jump: M, the increment window); ``tuning``:
        the ``jump_*`` gates."""
        t = tuning if tuning is not None else ControlTuning()
        self._w = 1.0 / t.jump_noise_samples
        self._n_avg = t.jump_noise_samples
        self._min_n = t.jump_min_samples
        self._jump2 = t.jump_sigmas * t.jump_sigmas
        self._ratio2 = t.jump_ratio_sigmas * t.jump_ratio_sigmas
        self._settle = settle_samples
        self.reset()

    def reset(self) -> None:
        """No previous sample, no noise estimate."""
        self._n = 0
        self._var = 0.0
        self._x = self._y = math.nan
        self.ratio = math.nan
        self._gain = 1.0
        self._hold = 0

    def break_chain(self) -> None:
        """The next sample does not follow the last one seen (samples were missed): it only
        starts a new chain of increments."""
        self._x = self._y = math.nan

    def update(self, position_m: float, spool_integral_m: float, gain: float, settled: bool) -> bool:
        """One sample: the position reading (m), the running spool integral K_c·∫y_v (m), the
        sensor's increment gain θ_prod and whether it is settled. True when the reading jumped
        since the last sample. Within ``settle_samples`` of a jump, and while θ_prod is not
        settled, the last settled gain is used instead."""
        if self._hold > 0:  # θ_prod's increments still span the last jump
            self._hold -= 1
            gain = self._gain
        elif settled:
            self._gain = gain
        else:
            gain = self._gain
        y_prev, x_prev = self._y, self._x
        self._y, self._x = position_m, spool_integral_m
        if y_prev != y_prev:  # NaN: the first sample of a chain
            return False
        dy = position_m - y_prev
        dx = gain * (spool_integral_m - x_prev)
        if dx >= 0.0:
            outside = -dy if dy < 0.0 else (dy - dx if dy > dx else 0.0)
        else:
            outside = dy if dy > 0.0 else (dx - dy if dy < dx else 0.0)
        n, var = self._n, self._var
        if n >= self._min_n and outside * outside > self._jump2 * var:
            self._hold = self._settle
            # the sensor's gain changed by y_now/y_before once the motion over the sample (taken
            # at the full flow) is taken out; unknown where the reading is within the noise of 0
            far = y_prev * y_prev > self._ratio2 * var
            self.ratio = (position_m - dx) / y_prev if far else math.nan
            return True
        r = dy - dx
        n += 1
        self._n = n
        self._var = var + (self._w if n > self._n_avg else 1.0 / n) * (r * r - var)
        return False
