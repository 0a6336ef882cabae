"""The "do no harm" monitor: an independent consistency check beside the supervisors.

The supervisors pick, per channel, the model that explains the channel's own data best. That
never says whether the selected models together explain the motion, nor whether compensating
with them is better than not compensating at all. This monitor answers the first question
with a witness the banks do not use, and falls back to nominal compensation (the plain PI
loop's behaviour, ``nrc``) while the answer is no:

* ``PRODUCT_MISMATCH``: the position channel's gain in use times k̂_Q, θ_used = θ̂_D·k̂_Q, and
  the offset-free increment estimate of k_DFT·k_Q (θ_prod, :meth:`.Increments.product`)
  deviate from 1 in opposite directions, each by more than ``min_deviation``, while θ_prod is
  fresh (an excited increment within the last M samples) and settled (moved by less than
  ``min_deviation`` over the last M samples: an increment that spans a sensor jump gives a
  meaningless θ_prod for M samples). The level regression of the position bank takes any x̂
  offset for a gain; the increments have none, and a disagreement in direction is never noise.
  Likewise the failed-sensor model (θ_used < 0.15) while θ_prod ≥ 0.5: the sensor follows the
  spool. Not checked while the position channel is guarded (the loop runs on x̂ then).
* ``ESTIMATE_AT_LIMIT``: an adaptive model in use sits at its clip (θ̂_D at its upper limit or
  θ̂_L at its lower one): the adaptive law hit a wall instead of converging.

A rule must hold for ``confirm`` updates in a row to enter the fallback; the fallback is left
after ``reengage`` updates in a row with no rule firing. Every entry is counted, with its reason.
"""

from __future__ import annotations

from enum import IntEnum


class FallbackReason(IntEnum):
    """Why the monitor fell back to nominal compensation (DBC CTRL_STATS ``FallbackReason``)."""

    NONE = 0
    PRODUCT_MISMATCH = 1
    ESTIMATE_AT_LIMIT = 2


#: the reasons bound once (looking up an enum member on its class costs several attribute reads)
_NONE = FallbackReason.NONE
_MISMATCH = FallbackReason.PRODUCT_MISMATCH
_AT_LIMIT = FallbackReason.ESTIMATE_AT_LIMIT


class HarmMonitor:
    """Consistency check with hysteresis in time; :attr:`fallback` True means: compensate
    nominally (k̂_LOE = k̂_DFT = k̂_Q = 1 in the loop, the raw sensor fed back)."""

    __slots__ = (
        "_alive",
        "_confirm",
        "_failed_below",
        "_i",
        "_min_dev",
        "_ok",
        "_pending",
        "_reengage",
        "_ring",
        "_streak",
        "fallback",
        "fallbacks",
        "reason",
    )

    def __init__(
        self,
        min_deviation: float,
        settle_samples: int,
        confirm: int,
        reengage: int,
        failed_below: float,
        alive: float,
    ) -> None:
        """``min_deviation``: |θ − 1| that counts as a deviation; ``settle_samples``: M;
        ``confirm``/``reengage``: updates in a row to enter/leave the fallback;
        ``failed_below``: θ_used of the failed-sensor model; ``alive``: θ_prod of a live
        sensor (the tuning's ``sensor_failed_below`` and ``monitor_sensor_alive``)."""
        self._min_dev = min_deviation
        self._failed_below = failed_below
        self._alive = alive
        self._confirm = max(1, confirm)
        self._reengage = max(1, reengage)
        self._ring = [1.0] * max(1, settle_samples)
        self.fallbacks = 0
        self.reset()

    def reset(self) -> None:
        """Not in fallback, no history (the count of fallbacks is kept)."""
        self._ring = [1.0] * len(self._ring)
        self._i = 0
        self._streak = 0
        self._ok = 0
        self._pending = FallbackReason.NONE
        self.fallback = False
        self.reason = FallbackReason.NONE

    def update(self, theta_used: float, theta_prod: float, prod_fresh: bool, at_limit: bool) -> bool:
        """One fresh sample: θ_used = θ̂_D·k̂_Q in use, θ_prod and whether it is fresh, whether an
        adaptive estimate in use is at its clip. Returns :attr:`fallback`.

        The rule that fires (the module's: the clip first, then on a fresh, settled θ_prod the
        mismatch rules) is judged here, θ_prod's history advanced, then the hysteresis in time:
        one call per sample, as this runs on every fresh sample."""
        ring, i, min_dev = self._ring, self._i, self._min_dev
        settled = abs(theta_prod - ring[i]) < min_dev
        ring[i] = theta_prod
        self._i = (i + 1) % len(ring)
        r = _NONE
        if at_limit:
            r = _AT_LIMIT
        elif prod_fresh and settled:
            du, dp = theta_used - 1.0, theta_prod - 1.0
            if du * dp < 0.0 and abs(du) > min_dev and abs(dp) > min_dev:
                r = _MISMATCH
            elif theta_used < self._failed_below and theta_prod >= self._alive:
                r = _MISMATCH  # "failed" sensor that follows the spool
        if r is not _NONE:
            self._ok = 0
            self._streak = self._streak + 1 if r == self._pending else 1
            self._pending = r
            if not self.fallback and self._streak >= self._confirm:
                self.fallback = True
                self.reason = r
                self.fallbacks += 1
            return self.fallback
        self._streak = 0
        self._pending = _NONE
        if self.fallback:
            self._ok += 1
            if self._ok >= self._reengage:
                self.fallback = False
                self._ok = 0
        return self.fallback
