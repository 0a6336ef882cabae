"""A spool overlap the plant has shown: x̂ then integrates no spool inside the band.

The design model is critically lapped: any spool moves the piston, ``ẋ = K_c·y_v``. A real valve
may be overlapped: inside ±overlap of null its lands cover the ports and the piston stands still.
x̂ integrating a spool that chatters inside that band (a loop holding still) travels while the
reading does not, and the position bank takes the difference for a failed sensor. The
uncertainty set names the widest overlap, ``spool_overlap_max_m``; whether the plant has one is
the plant's to show, as its flow gain is. A sensor that sticks while the loop holds still looks
the same inside the band (the two differ only once the spool opens beyond it), so the band is not
assumed: it is learned while the sensor is trusted and shows it is alive.

:class:`SpoolOverlap` watches the stretches the spool spends inside the band while the position
channel is healthy: x̂'s travel over the stretch (``K_c·Ts·Σ y_v``, m) against the reading's
change Δy (m). A stretch ends when the spool leaves the band, the channel stops being healthy,
or x̂ has travelled ``overlap_evidence_snr`` times the reading's noise σ̂ in it. It is evidence
if it spans at least an increment window (M samples); if the reading changed on more than half
of its samples and never held one value for M samples (a stuck reading repeats itself to the
bit; a live one shows its noise); and if the reading moved neither against x̂ nor further than
θ̂ times x̂'s travel by more than ``overlap_confidence`` times its noise (no overlap explains
that: a jump, a creep). The share of x̂'s in-band travel the piston made is the least-squares g
of Δy = g·θ̂·Δx̂ over the evidence (θ̂: the position gain in use); its standard error is the
larger of the residuals' own spread (a piston settling after a transient moves in the band as
x̂ does not) and the reading's noise (each Δy carries two readings': √2·σ̂). Once, over at
least ``overlap_min_stretches`` stretches, g ± ``overlap_confidence`` standard errors lies
within ±``overlap_shown_below`` of 0 (an overlapped valve passes nothing in its band; a piston
moving against x̂ is no overlap; a share known no better is no verdict), the overlap is shown:
x̂ integrates g (at least 0) times the spool inside the band (:meth:`ModelPosition.integrate`),
and the position channel starts over from the sensor (what it concluded was reached on a model
without the overlap). A critically lapped plant (g ≈ 1) does not show one.
"""

from __future__ import annotations

import math

from ..tuning import ControlTuning


class SpoolOverlap:
    """The band gain g of the spool's in-band stretches; :meth:`update` once per fresh sample."""

    __slots__ = (
        "_band",
        "_changed",
        "_dx",
        "_frozen",
        "_kts",
        "_m",
        "_min_n",
        "_n",
        "_open",
        "_run",
        "_shown_below",
        "_snr",
        "_steps",
        "_sxr",
        "_sxx",
        "_syy",
        "_y0",
        "_y_last",
        "_z",
        "gain",
    )

    def __init__(self, velocity_gain_1_s: float, ts_s: float, tuning: ControlTuning) -> None:
        """``velocity_gain_1_s``: K_c (1/s) of x̂; ``ts_s``: sample time (s); ``tuning``: the
        band ``spool_overlap_max_m`` and the ``overlap_*`` evidence settings."""
        t = tuning
        self._kts = velocity_gain_1_s * ts_s
        self._band = t.spool_overlap_max_m
        self._snr = t.overlap_evidence_snr
        self._z = t.overlap_confidence
        self._min_n = t.overlap_min_stretches
        self._shown_below = t.overlap_shown_below
        self._m = t.increment_window
        self.forget()

    def forget(self) -> None:
        """Nothing known of the plant (power-on): no overlap shown (g = 1), nothing learned."""
        #: the band gain x̂ integrates the in-band spool with (1: critically lapped, the model)
        self.gain = 1.0
        self._sxx = self._sxr = self._syy = 0.0
        self._n = 0
        self._close()

    def reset(self) -> None:
        """No stretch open; what was learned of the plant is kept (a fail-safe recovery does not
        change the valve; :meth:`forget` forgets it)."""
        self._close()

    def _close(self) -> None:
        self._open = False
        self._dx = self._y0 = self._y_last = 0.0
        self._steps = self._changed = self._run = 0
        self._frozen = False

    def update(self, spool_m: float, position_m: float, healthy: bool, theta: float, noise_m: float) -> bool:
        """One fresh sample: the spool LVDT (m), the position reading (m), whether the position
        channel is healthy (trusted, unguarded, on its nominal model, no hypothesis, one sample
        since the last), the position gain in use θ̂ (1) and the reading's noise σ̂ (m). Returns
        True on the sample the overlap becomes shown (:attr:`gain` then below 1)."""
        band = self._band
        if -band < spool_m < band and healthy:
            if not self._open:  # the stretch starts at this sample's reading
                self._open = True
                self._y0 = self._y_last = position_m
                return False
            self._dx += self._kts * spool_m
            self._steps += 1
            if position_m != self._y_last:
                self._changed += 1
                self._run = 0
            else:
                self._run += 1
                if self._run >= self._m:  # M readings alike: a frozen reading, no evidence
                    self._frozen = True
            self._y_last = position_m
            if self._steps < self._m or abs(self._dx) < self._snr * noise_m:
                return False
        elif not self._open:
            return False
        # the stretch ends (the spool left the band, the channel is not healthy, or x̂ travelled
        # far enough in it): evidence if it spans an increment window and the reading showed
        # life on most of its samples (a reading that froze inside it did not)
        dx, dy = self._dx, self._y_last - self._y0
        evidence = (
            self._steps >= self._m and 2 * self._changed > self._steps and not self._frozen and dx != 0.0
        )
        self._close()
        if not evidence or theta <= 0.0 or noise_m <= 0.0:
            return False
        # no overlap explains a reading that moved against x̂ or further than it, beyond the
        # noise (a jump of the reading, a creep, a load): the stretch is not about the band
        u = dy if dx > 0.0 else -dy
        slack = self._z * math.sqrt(2.0) * noise_m  # Δy: a difference of two readings
        if u < -slack or u > theta * abs(dx) + slack:
            return False
        self._sxx += dx * dx
        self._sxr += dy * dx
        self._syy += dy * dy
        n = self._n = self._n + 1
        if self.gain != 1.0 or n < self._min_n:
            return False
        # the least-squares share Δy = g·θ·Δx̂, and its standard error: the residuals' own
        # spread (a piston settling after a transient moves in the band as x̂ does not) or the
        # reading's noise (each Δy carries two readings': variance 2σ̂²), the larger
        sxx, sxr = self._sxx, self._sxr
        g = sxr / (theta * sxx)
        rss = self._syy - sxr * sxr / sxx
        se = math.sqrt(max(rss / (n - 1), 2.0 * noise_m * noise_m) / sxx) / theta
        # shown: the share's interval of ``overlap_confidence`` standard errors lies within
        # ±``overlap_shown_below`` of 0 (an overlapped valve passes nothing in its band; a share
        # well below 0 is no overlap, one known no better is no verdict)
        if abs(g) + self._z * se <= self._shown_below:
            self.gain = g if g > 0.0 else 0.0
            return True
        return False
