"""Whose is a position-channel gain change: the sensor's (compensate it) or the flow gain's?

The position bank fits ``y_s = θ·x̂`` with x̂ integrating the spool at the nominal flow gain, so
both a sensor drift (k_DFT) and a flow-gain loss (k_Q) move θ. Compensating a flow-gain loss as a
drift makes the loop track ``k_Q·x_d``; compensating nothing costs what the plain PI loop costs.
So the position model in use is compensated only once independent evidence has attributed it to
the sensor; until then the loop feeds the raw sensor back (``LoopBase.position_nominal``).
The evidence, each enough on its own:

* the load-pressure test decided H_D (:class:`.PressureTest`,
  :attr:`.PressureTest.sensor_favoured`; an increment gain θ_prod above 1 is no evidence on
  its own: a flow gain may be above the model's);
* the model changed while the piston was at rest (θ_prod stale: no excited increment) from one
  that agreed with θ_prod when the motion stopped, and the reading moved since beyond the
  model's travel, by the model's ratio (:meth:`SensorAttribution._moved_at_rest`): a flow gain
  moves nothing without flow, a sensor gain moves the reading at once;
* the reading jumped (:class:`.LevelJump`) by a gain ratio ρ, and within ``jump_hold_s``
  the model moved to ρ times the gain in use before the jump (a model change the jump does not
  explain, a flow-gain loss beside it, is left to the pressure test). A model so attributed
  stays attributed while it stays within ``min_deviation``/2 of the gain the jump explained,
  also inside the band the pressure test cannot resolve.

The reading alone cannot tell a gain change from an offset (a bias stepping in jumps the
reading too, by a ratio (y + b)/y), but the increments can: an offset moves no increment. So
an attribution made by a jump or at rest is verified once the product settles again on
increments that span no jump: it moved by the ratio (a gain change: it stands) or stayed where
it was (an offset: the attribution is withdrawn, :meth:`.PressureTest.withdraw_sensor`, and the
offset is left to the plain loop).

Every attribution but the last is the pressure test's state (:meth:`.PressureTest.decide_sensor`),
which H_Q evidence can still overturn. An attribution belongs to the deviation it was made for: a
switch of the position supervisor to a model whose gain differs by more than ``min_deviation``
from the one in use, with no evidence on or after it, is a new deviation and is not compensated
(a model an RIA had walked to 0.16 at rest, switched to long after a drift was attributed, sent
the piston 3 mm away: campaign run 1453).
"""

from __future__ import annotations

import math

from ..tuning import ControlTuning
from .jump import LevelJump
from .protocols import IncrementEvidence, PressureEvidence


class SensorAttribution:
    """Per fresh sample (:meth:`update`): may the position model in use be compensated?"""

    __slots__ = (
        "_attributed",
        "_chain",
        "_failed_below",
        "_gain",
        "_hold",
        "_inc",
        "_jump_decided",
        "_kd_before",
        "_last_ratio",
        "_left",
        "_level_ref",
        "_min_change",
        "_min_dev",
        "_model",
        "_prod_before",
        "_prod_from",
        "_prod_jumped",
        "_pt",
        "_rest_from",
        "_rest_moved",
        "_rest_snr",
        "_theta_before",
        "_to",
        "_unexplained",
        "_verify_z",
        "_was_guarded",
        "by_jump",
        "jump",
        "jump_gain",
        "jumped_since_guard",
        "since_guard",
        "verified_gain",
    )

    def __init__(
        self,
        inc: IncrementEvidence,
        pressure: PressureEvidence,
        ts_s: float,
        failed_below: float,
        tuning: ControlTuning | None = None,
    ) -> None:
        """``inc``, ``pressure``: the increment product and the load-pressure test of this
        controller; ``ts_s``: sample time (s); ``failed_below``: θ of the failed-sensor model;
        ``tuning``: the ``jump_*`` gates."""
        t = tuning if tuning is not None else ControlTuning()
        self._inc = inc
        self._pt = pressure
        self._min_dev = pressure.min_deviation
        self._failed_below = failed_below
        self._hold = max(1, round(t.jump_hold_s / ts_s))
        self._rest_snr = t.rest_reading_snr
        self._verify_z = t.verify_significance
        self._min_change = t.jump_min_change
        self.jump = LevelJump(inc.increment_window, t)
        self.reset()

    def reset(self) -> None:
        """Nothing attributed, no jump seen."""
        self.jump.reset()
        self._level_ref = 1.0  # θ̂_D of the model in use when θ_prod was last fresh
        #: the reading and the model's travel (spool + creep integral) then (m)
        self._rest_from = (0.0, 0.0)
        self._rest_moved = 0  # samples in a row the reading has shown the change since
        self._left = 0  # samples left in which a model change the jump explains is the sensor's
        self._to = 1.0  # the gain such a model moves to
        self._kd_before = 1.0  # θ̂_D in use before the last jump
        self._attributed = False  # the last update attributed the model in use to the sensor
        #: the sensor gain the reading's jumps since the reset account for, the product of their
        #: ratios (NaN: a jump whose ratio was unknown, near x = 0)
        self._chain = 1.0
        self._last_ratio = 1.0  # the ratio of the jump (or change at rest) being verified
        self._gain = math.nan  # the model a jump explained, while it is in use
        self._prod_before = 1.0  # θ_prod when last settled with no jump to verify
        #: the product a gain jump predicts (θ_prod before it × its ratio) until the settled
        #: product confirms or refutes it; NaN: nothing to verify
        self._prod_jumped = math.nan
        self._prod_from = 1.0  # the gain the jump being verified is judged from
        self._jump_decided = False  # the sensor was decided on the jump being verified
        self._model = -1  # the position model in use at the last sample
        self._theta_before = 1.0  # its θ̂_D
        self._unexplained = False  # the model in use was switched to without evidence since
        #: excited increments of θ_prod taken since the position guard rose (0: not guarded)
        self.since_guard = 0
        #: the reading jumped since the position guard rose (False: not guarded)
        self.jumped_since_guard = False
        #: the sensor gain the last jump of the reading went to (θ̂_D before it × its ratio),
        #: kept until the position guard falls; NaN: none
        self.jump_gain = math.nan
        self._was_guarded = False
        #: the product the last gain jump of the reading was verified at (the settled product
        #: moved by the jump's ratio: a gain change, which scales the reading about its zero);
        #: NaN: none since the reset or the last jump
        self.verified_gain = math.nan
        #: the model in use is the gain a jump of the reading explained: the reading stepped, so
        #: its compensation applies at once (no ramp)
        self.by_jump = False

    def _settled_product(self, theta_prod: float) -> None:
        """The product settled on excited increments none of which spans a jump. After a jump
        it tells a gain change (the product moved by the jump's ratio) from an offset, a bias
        stepping in (the product stayed where it was): the attribution such a jump made is
        withdrawn — an offset is left to the plain loop."""
        to = self._prod_jumped
        if to == to and abs(theta_prod - self._prod_from) < abs(theta_prod - to):
            self._left = 0
            self._chain /= self._last_ratio  # an offset: no part of the sensor's gain
            if self._jump_decided:
                self._pt.withdraw_sensor()
            self._gain = self.jump_gain = math.nan
        elif to == to:
            self.verified_gain = theta_prod
        self._prod_jumped = math.nan
        self._jump_decided = False
        self._prod_before = theta_prod

    def _verifiable(self) -> bool:
        """A jump (or a change at rest) awaits verification and the increments since tell its
        two readings apart: the least-squares gain since it (:attr:`.Increments.since_jump_fit`)
        lies ``verify_significance`` standard errors off the midpoint between the gain before
        and the gain the jump predicts. Under noise the product may never settle; this decides
        as soon as the evidence does."""
        to = self._prod_jumped
        if not to == to:
            return False
        r, se = self._inc.since_jump_fit
        return abs(r - 0.5 * (to + self._prod_from)) > self._verify_z * se  # False while NaN

    def _verified_from(self) -> float:
        """The gain before a jump that its verification compares the settled product with: the
        position model in use when it agrees with the last settled product within
        ``min_deviation`` (the model averages far more increments than one settled product,
        whose noise made a drift of 8 % look like an offset), else that product."""
        kd, prod = self._kd_before, self._prod_before
        return kd if abs(kd - prod) < self._min_dev else prod

    def _moved_at_rest(self, position_m: float, travel_m: float, theta_d: float) -> bool:
        """A model change with the piston at rest that the reading shows: θ̂_D moved off
        ``level_ref`` (the model when the motion stopped) by more than ``min_deviation``, and the
        reading moved since beyond what the model's travel explains (θ_prod times it) by
        ``rest_reading_snr`` σ̂ of its noise, ``increment_window`` samples in a row. A gain change
        at rest moves the reading by Δk·x with nothing else moving; a stuck reading departs from
        the travel the loop commands; a level model catching up with an offset of x̂ (read as a
        gain near x = 0) moves neither. ``position_m``: the reading (m); ``travel_m``: the
        spool + creep integral (m of piston travel at the nominal flow gain)."""
        fl = self._inc
        changed = abs(theta_d - self._level_ref) > self._min_dev and theta_d >= self._failed_below
        if not (fl.at_rest and changed):
            self._rest_moved = 0
            return False
        y0, s0 = self._rest_from
        moved = abs(position_m - y0 - fl.theta_prod * (travel_m - s0))
        self._rest_moved = self._rest_moved + 1 if moved >= self._rest_snr * fl.reading_noise_m else 0
        return self._rest_moved >= fl.increment_window and self._shows_ratio(position_m - y0, y0, theta_d)

    def _shows_ratio(self, moved_m: float, y0_m: float, theta_d: float) -> bool:
        """At rest the reading scales with the sensor's gain: a model at ``theta_d`` from
        ``level_ref`` says the reading ``y0_m`` moved by y0·(θ̂_D/level_ref − 1). True when the
        reading's move ``moved_m`` (m) is that within ``min_deviation`` of y0 — a model still on
        its way (an RIA overshooting a level step) is not yet the reading's. No ratio to check
        from a failed sensor's model (level_ref below ``sensor_failed_below``)."""
        ref = self._level_ref
        if not ref >= self._failed_below:
            return True
        return abs(y0_m * (theta_d / ref - 1.0) - moved_m) <= self._min_dev * abs(y0_m)

    def update(
        self, position_m: float, theta_d: float, model: int, guarded: bool, broken: bool, trusted: bool
    ) -> bool:
        """One fresh sample, after the flow-gain test: the position reading (m), the position
        model's θ̂_D in use and its slot (``model``), whether the position guard is up, whether
        samples were missed and not redone (``broken``), whether the loop trusted the sensor at
        the last fresh sample.
        True when θ̂_D is attributed to the sensor: by evidence, or by an attribution that stands
        for this model (not made unexplained by a switch without evidence)."""
        fl, pt = self._inc, self._pt
        if not guarded:
            self.since_guard = 0
            self.jumped_since_guard = False
            if self._was_guarded:
                self.jump_gain = math.nan
        elif fl.product_updated:
            self.since_guard += 1
        self._was_guarded = guarded
        travel = fl.spool_integral_m + fl.creep_integral_m
        if fl.product_fresh:
            # the level model agreed with the increments when the motion stopped: a change at
            # rest is then the reading's; one that does not agree may still be adapting
            self._level_ref = theta_d if abs(theta_d - fl.theta_prod) < self._min_dev else math.nan
            self._rest_from = (position_m, travel)
            self._rest_moved = 0
        elif self._moved_at_rest(position_m, travel, theta_d):
            # a model change with the piston at rest (False while NaN): verified like a jump
            if not pt.sensor_decided and self._level_ref >= self._failed_below:
                self._prod_from = self._prod_before
                self._last_ratio = theta_d / self._level_ref
                self._chain *= self._last_ratio
                self._prod_jumped = self._prod_before * self._last_ratio
                self._jump_decided = True
                fl.restart_fit()
            pt.decide_sensor(fl.theta_prod)
        j = self.jump
        if broken:  # the spool integral does not span the samples missed
            j.break_chain()
        elif j.update(
            position_m, fl.spool_integral_m + fl.creep_integral_m, fl.theta_prod, fl.product_settled
        ):
            fl.note_jump()
            self.verified_gain = math.nan
            self.jumped_since_guard = guarded
            if trusted and math.isfinite(j.ratio):  # a ratio to a gain the loop trusted
                # a decision an earlier jump or change at rest made, still unverified, is
                # verified with this one: it is about the same reading, so this jump chains on
                # the product that change predicts, from the gain before it
                decided = self._jump_decided and self._prod_jumped == self._prod_jumped
                self._left = self._hold
                # the jump scales the gain the reading had: the model in use when it was the
                # sensor's; else the plant's own product times what the jumps so far account for
                # (a deviation no jump made, a flow loss or a plant off the model, is no part
                # of the sensor's gain)
                chain = self._chain
                before = self._kd_before if self._attributed or chain != chain else self._pt.k_base * chain
                self._to = self.jump_gain = before * j.ratio
                if decided:
                    self._prod_jumped *= j.ratio
                    self._last_ratio *= j.ratio
                else:
                    self._prod_from = self._verified_from()
                    self._prod_jumped = self._prod_from * j.ratio
                    self._last_ratio = j.ratio
                self._jump_decided = decided
            self._chain *= j.ratio  # NaN near x = 0: the reading's gain is no longer known
        elif self._verifiable():
            self._settled_product(fl.since_jump_fit[0])
        elif fl.product_settled and fl.product_updated:
            self._settled_product(fl.theta_prod)
        if self._left > 0:
            self._left -= 1
            moved = abs(theta_d - self._kd_before) > self._min_change
            if moved and abs(theta_d - self._to) < self._min_dev and theta_d >= self._failed_below:
                # the product the jump predicts: θ_prod takes no increment for M samples after it
                to = self._prod_jumped
                pt.decide_sensor(to if to == to else fl.theta_prod)
                self._jump_decided = True
                self._gain = theta_d
                self._left = 0
        near = abs(theta_d - self._gain) <= 0.5 * self._min_dev  # False while NaN
        self.by_jump = near
        if not near:
            self._gain = math.nan
        if self._left == 0:
            self._kd_before = theta_d
        if model != self._model:  # a switch is a new deviation: the attribution of the last does
            # not carry over to it, unless the model's gain stays where it was
            self._unexplained = self._model >= 0 and abs(theta_d - self._theta_before) > self._min_dev
            self._model = model
        self._theta_before = theta_d
        if pt.sensor_current or near or not pt.sensor_decided:
            self._unexplained = False
        self._attributed = (pt.sensor_favoured or near) and not self._unexplained
        return self._attributed
