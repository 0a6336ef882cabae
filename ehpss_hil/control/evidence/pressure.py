"""The pressure test: is a deviation of the product a sensor drift (H_D) or a flow-gain change (H_Q)?

With the piston position and the spool LVDT alone only ``k_DFT·k_Q`` is identifiable: a flow-gain
loss looks exactly like a position-sensor drift to the position channel. The load pressure does
not go through the position sensor: ``P_L = k_LOE·k_Q·(m/A_h)·ẍ₁``, ẍ₁ the acceleration of a
unit-gain model driven by the applied-current echo. In closed loop the noise-driven valve
activity gives P_L enough model-predictable content that a likelihood ratio over an
exponentially weighted window (the evidence, :class:`.LoadPressure`) decides within tens of
milliseconds between H_D (k_Q = k_base, k_DFT = θ_pos/k_base) and H_Q (k_Q = θ_pos, sensor at
its gain; either sign). H_Q is entered at Λ > ``flow_gain_threshold`` and left at the opposite;
H_D, whose error costs more, is decided only at Λ < −``flow_gain_sensor_threshold``, on a product
that agrees with its average, and before the plant's pressure gain is learned only for an
averaged product beyond ``velocity_gain_uncertainty`` of the plant's flow gain
(:meth:`.PlantGain.fault_possible`). A decision ends only when neither θ_pos nor the position
bank's level model deviates. The compensation always uses θ_pos; only its split between the
sensor and the flow gain comes from the pressure, so the pressure noise never enters the loop.
docs/control.md §5 gives the derivation, the window's rules and the figures.
"""

from __future__ import annotations

from ...physics.params import PlantParams
from ..predictors import UnitPlantPredictor
from ..tuning import ControlTuning
from .likelihood import PressureWindow
from .loadpressure import LoadPressure
from .plantgain import PlantGain, ProductAverage


class PressureTest:
    """Decides H_D / H_Q each sample; :attr:`k_q` is 1.0 (H_D) or the estimated product (H_Q).
    The product θ_pos comes from :class:`.Increments`; this class holds the sensor gain a
    deviation is judged beside and the decision. The evidence — the unit-gain P_L model
    :attr:`model` (stepped by the sample clock between updates) and the window of P_L against it
    :attr:`window` — is :attr:`evidence` (a :class:`.LoadPressure`); what is known of the plant's
    own flow and pressure gains :attr:`plant` (a :class:`.PlantGain`)."""

    __slots__ = (
        "_avg",
        "_band",
        "_beside",
        "_by_test",
        "_failed_below",
        "_min_dev",
        "_min_evidence",
        "_on",
        "_on_d",
        "_s",
        "_s_held",
        "_theta_ref",
        "evidence",
        "flow_fault",
        "k_q",
        "llr",
        "model",
        "plant",
        "sensor_current",
        "sensor_decided",
        "window",
    )

    def __init__(self, plant: PlantParams, ts_s: float, tuning: ControlTuning | None = None) -> None:
        t = tuning if tuning is not None else ControlTuning()
        #: the evidence: the unit-gain P_L model and the window of P_L against it
        self.evidence = LoadPressure(plant, ts_s, t)
        #: the valve + cylinder at unit gains, stepped on the current echo by the sample clock
        self.model: UnitPlantPredictor = self.evidence.model
        #: P_L against the unit-gain prediction, over ``flow_gain_window_s``
        self.window: PressureWindow = self.evidence.window
        self._on = t.flow_gain_threshold
        self._on_d = t.flow_gain_sensor_threshold
        self._min_dev = t.flow_gain_min_deviation
        self._min_evidence = t.flow_gain_min_evidence_s / ts_s
        self._failed_below = t.sensor_failed_below
        #: the plant's own flow gain and pressure gain (kept across :meth:`reset`)
        self.plant = PlantGain(ts_s, t)
        self._band = t.pressure_gain_uncertainty
        self._avg = ProductAverage(t.increment_window, t.product_spread)
        self.reset()

    def forget_plant(self) -> None:
        """Nothing known of the plant (power-on): the model's flow gain, not seen yet, no
        pressure baseline."""
        self.plant.forget()

    @property
    def k_base(self) -> float:
        """The plant's own flow gain (:attr:`.PlantGain.k_base`): the nominal of both hypotheses."""
        return self.plant.k_base

    @property
    def plant_seen(self) -> bool:
        """The plant was seen at the model's flow gain (:attr:`.PlantGain.seen`)."""
        return self.plant.seen

    def reset(self) -> None:
        """At rest, hypothesis H_D (k_Q = 1 · k_base), empty window; what is known of the plant
        (its flow gain, whether it was seen at the model's, the pressure baseline) is kept: a
        fail-safe recovery does not change the plant (:meth:`forget_plant` forgets it)."""
        self.evidence.reset()
        self.k_q = self.k_base
        self.flow_fault = False
        self.llr = 0.0
        self._theta_ref = self.k_base
        self._avg.reset()  # θ_pos averaged over about M excited updates: H_Q's gain in the test
        self.sensor_decided = False
        #: the sensor's gain (relative to the plant's, θ_prod/k_base) H_D stands at: once the
        #: reading's level shows it, a later change of the product is judged beside it
        self._s = 1.0
        self._s_held = False  # the bank's model has shown s (the averaged product) since H_D was decided
        self._by_test = False  # H_D was decided by this test (not by a jump of the reading)
        self._beside = 1.0  # the sensor gain H_Q is judged beside on this sample
        #: H_D decided on this sample (Λ < −``flow_gain_sensor_threshold`` on enough evidence) or
        #: by :meth:`decide_sensor` since the last :meth:`update`
        self.sensor_current = False

    @property
    def min_deviation(self) -> float:
        """The smallest |θ_pos − 1| taken as a deviation to attribute (dimensionless)."""
        return self._min_dev

    def forget_attribution(self) -> None:
        """No hypothesis decided, no evidence (the plant model changed under them); the
        product, the creep and the pressure baseline kept."""
        self.flow_fault = self.sensor_decided = self.sensor_current = False
        self.k_q = self.k_base
        self.llr = 0.0
        self._theta_ref = self.k_base
        self._s = 1.0
        self._by_test = False
        self.restart()

    def decide_sensor(self, theta_prod: float) -> None:
        """Attribute the present deviation (the product at ``theta_prod``) to the sensor without
        the pressure test (the caller has independent evidence: a jump of the reading, a level
        change with the piston at rest); H_Q evidence can still overturn it."""
        if not self.flow_fault:
            if not self.sensor_decided:
                self._theta_ref = theta_prod
            self._s = theta_prod / self.k_base
            self._s_held = False
            self._by_test = False
            self.sensor_decided = self.sensor_current = True

    def withdraw_sensor(self) -> None:
        """The evidence the caller attributed the deviation to the sensor with (a jump) turned
        out to be no gain change: H_D no longer decided (the test may decide it again)."""
        if not self.flow_fault:
            self.sensor_decided = self.sensor_current = False
            self._s = 1.0

    def restart(self) -> None:
        """Empty the evidence window (the hypotheses or the pressure model changed); the
        decision stands until new evidence overturns it."""
        self.evidence.restart()

    def hold_off(self, samples: int) -> None:
        """Take no evidence for the next ``samples`` updates (the decision stands; see
        :meth:`.LoadPressure.hold_off`)."""
        self.evidence.hold_off(samples)

    def update(
        self,
        current_a: float,
        pressure_pa: float,
        theta_l: float,
        theta_pos: float,
        theta_level: float = 1.0,
        healthy: bool = False,
        fresh: bool = True,
        updated: bool = True,
    ) -> float:
        """One sample: current echo (A), measured P_L (Pa), k̂_LOE, the product estimate
        θ_pos = k_DFT·k_Q and the position bank's level estimate θ_level (the gain its model in
        use gives the sensor); returns k̂_Q (1.0 under H_D). A decision ends only when neither
        θ_pos nor θ_level deviates: θ_pos wanders at low excitation, the bank's model stands.
        ``healthy``: the spool channel has settled on its model (k̂_LOE is known), so a sample
        with nothing deviating may teach the pressure baseline. ``fresh``: θ_pos had an excited
        increment within the last M samples (:attr:`.Increments.product_fresh`); ``updated``: it
        had one on this sample, and ``increment_window`` (M) of them make the average θ_pos H_Q is judged
        with (one sample's θ_pos wanders with the position noise: a dip is no evidence)."""
        self.model.propagate(current_a)
        self.sensor_current = False
        if updated:
            self._average(theta_pos)
        if self.flow_fault and theta_pos < self._failed_below:
            # a failed sensor is never a flow-gain loss, also while evidence is held off or
            # stale (k̂_Q = θ_pos ≈ 0 would divide the position by nothing)
            self.flow_fault = False
            self.k_q = self.k_base
        ev = self.evidence
        if ev.held():  # no evidence now (hold_off): the decision stands
            return self.k_q
        if not fresh:  # θ_pos is stale (no excited increment): nothing to test
            return self.k_q
        if ev.loe_moved(theta_l, healthy) and (self.flow_fault or self.sensor_decided):
            # a decision taken stands on the evidence gathered since the LOE moved
            ev.restart()
        beside = self._judged_beside(theta_pos, theta_level)
        if self._unseen_gain_over(theta_pos, theta_level) or self._no_deviation(
            theta_pos, theta_level, beside, theta_l, pressure_pa, healthy
        ):
            self.llr = 0.0
            self.k_q = self.k_base
            return self.k_q
        self._gather(theta_pos, theta_l, pressure_pa, beside)
        self._decide(theta_pos)
        self._adopt(theta_pos)
        self.k_q = theta_pos / self.sensor_gain if self.flow_fault else self.k_base
        return self.k_q

    def _average(self, theta_pos: float) -> None:
        """An excited update of θ_pos: its average over about M of them (H_Q's gain in the test)
        and its wander, and whether the average has stood at 1 for ``plant_seen_s``
        (:attr:`plant_seen`)."""
        self._avg.add(theta_pos)
        self.plant.observe(self._avg.mean)

    def _judged_beside(self, theta_pos: float, theta_level: float) -> float:
        """The sensor gain a change of the product is judged beside on this sample (1: none).
        While H_D stands and the averaged product and the bank's model, the reading's level,
        agree, that is the sensor's gain (it follows a drift that keeps moving); a later move
        of the product off it, or off the gain H_Q was entered beside, is a new change."""
        kb = self.k_base
        dev = self._min_dev * kb
        if self.sensor_decided and abs(theta_level - self._avg.mean) < dev:
            self._s = self._avg.mean / kb
            self._s_held = True
        sg = self.sensor_gain
        beside = self._beside = sg if sg != 1.0 and abs(theta_pos / sg - kb) >= dev else 1.0
        return beside

    def _unseen_gain_over(self, theta_pos: float, theta_level: float) -> bool:
        """Before the plant has shown the model's flow gain, an H_D this test decided ends when
        the product sits at the gain decided and the bank's model, the reading's level, does not
        show it: that gain is the plant's own (a creep or unequal areas move the increments,
        not the level), no gain of the sensor."""
        sd, kb = self._s, self.k_base
        if not (self.sensor_decided and self._by_test and not self.plant_seen and sd != 1.0):
            return False
        dev = self._min_dev * kb
        if abs(theta_pos / sd - kb) < dev and abs(theta_level - kb) < dev:
            self._end_episode()
            return True
        return False

    def _no_deviation(
        self,
        theta_pos: float,
        theta_level: float,
        beside: float,
        theta_l: float,
        pressure_pa: float,
        healthy: bool,
    ) -> bool:
        """Whether there is no deviation to test (H_D whatever the evidence). With the bank's
        model at the plant's gain too the episode is over (the window starts afresh when a
        deviation appears). A healthy sample with nothing attributed, the bank's model and the
        *averaged* product at the plant's gain (one θ_pos wanders with the position noise)
        teaches the pressure baseline."""
        kb = self.k_base
        dev = self._min_dev * kb
        level_at_base = abs(theta_level - kb) < dev
        if (
            healthy
            and level_at_base
            and beside == 1.0
            and not (self.flow_fault or self.sensor_decided)
            and abs(self._avg.mean - kb) < dev
        ):
            self.evidence.teach(self.plant.baseline, theta_l * kb, pressure_pa)
        if self.flow_fault or beside != 1.0 or abs(theta_pos - kb) >= dev:
            return False
        if level_at_base and (self.window.w > 0.0 or self.sensor_decided):
            self._end_episode()
        return True

    def _gather(self, theta_pos: float, theta_l: float, pressure_pa: float, beside: float) -> None:
        """The sample into the window (emptied first when what it held is about another
        deviation) and Λ of H_Q beside ``beside`` against H_D. Until the plant's own pressure
        gain is learned each hypothesis' gain is known within ``pressure_gain_uncertainty``;
        H_Q's only as well as the product: ± ``product_spread`` times its mean step between
        excited increments (the wander the position noise gives it)."""
        ev = self.evidence
        if self.flow_fault or self.sensor_decided:
            if abs(theta_pos - self._theta_ref) > self._min_dev:
                # an attributed deviation moved: gather evidence afresh (the attribution stands
                # until the new evidence overturns it)
                self._theta_ref = theta_pos
                ev.restart()
        elif ev.moved_off(self._avg.mean):
            # the product moved off a deviation the window held without deciding (a plant the
            # uncertainty leaves ambiguous): that evidence is about the plant, not the new
            # change; while unattributed and undecided the product is still converging on the
            # one deviation and the evidence is kept
            ev.restart()
        ev.add(pressure_pa, self._avg.mean)
        g = self.pressure_gain * theta_l
        band = 0.0 if self.plant.baseline.learned else self._band
        # H_Q: the flow gain is the product less the sensor gain it is judged beside
        spread = self._avg.reach * g / beside
        self.llr = ev.window.llr(g * self.k_base, g * self._avg.mean / beside, spread, band)

    def _end_episode(self) -> None:
        """The deviation is over: H_D no longer decided, no sensor gain carried, the window
        empty (it starts afresh when a deviation appears)."""
        self._theta_ref = self.k_base
        self.sensor_decided = False
        self._s = 1.0
        self.restart()

    def _adopt(self, theta: float) -> None:
        """A deviation the window held undecided for ``undecided_evidence`` becomes the plant's
        flow gain when :meth:`.PlantGain.adopt` takes it (inside the velocity-gain uncertainty,
        before the plant has shown its own); the window starts afresh."""
        if self.flow_fault or self.sensor_decided or not self.evidence.undecided:
            return
        if self.plant.adopt(self._avg, theta):
            self._theta_ref = self.plant.k_base
            self.restart()

    @property
    def sensor_gain(self) -> float:
        """The sensor's gain H_Q is judged beside (relative to the plant's flow gain): while H_D
        stands, the averaged product once the bank's model shows it too; under H_Q, the gain it
        was entered beside; else 1 (also for a failed sensor's, below ``sensor_failed_below``:
        no flow gain is judged beside it)."""
        s = self._s
        stands = self.flow_fault or (self.sensor_decided and self._s_held)
        return s if stands and s >= self._failed_below else 1.0

    @property
    def pressure_gain_learned(self) -> bool:
        """The plant's pressure gain was learned (``baseline_min_s`` of healthy operation)."""
        return self.plant.baseline.learned

    def compensated_product(self, theta_pos: float) -> float:
        """The product H_Q compensates with: this sample's θ_pos, or its average over about M
        excited increments where the product wanders by ``min_deviation`` or more
        (``product_spread`` mean steps: 10–20 µm of position noise) — a current divided by one
        noisy θ_pos carries that noise into the loop, while a clean product follows what moves
        it at once (a single-rod cylinder's gain changing with the direction of travel)."""
        avg = self._avg
        return avg.mean if avg.reach >= self._min_dev * self.k_base else theta_pos

    @property
    def pressure_gain(self) -> float:
        """The plant's load pressure over the model's, learned while nothing deviated (both
        hypotheses predict with it; :class:`.PressureBaseline`)."""
        return self.plant.baseline.gain

    @property
    def sensor_favoured(self) -> bool:
        """The present deviation may be compensated as the sensor's: H_D decided (a product
        above 1 is no evidence for the sensor: a flow gain may be above the model's too)."""
        return not self.flow_fault and self.sensor_decided

    @property
    def attributed(self) -> bool:
        """The present deviation of the product has been attributed (H_Q entered or H_D
        decided on enough evidence)."""
        return self.flow_fault or self.sensor_decided

    def _decide(self, theta: float) -> None:
        """Enter H_Q on strong evidence and a real deviation whose averaged product stands
        ``product_spread`` mean steps above ``sensor_failed_below`` (a dead reading's product
        wanders up to 0.3–0.4 under position noise); leave it on strong counter-evidence (or a
        product below ``sensor_failed_below``: a failed sensor is never a flow-gain loss).
        Decide H_D on strong evidence for it only where this sample's product agrees with the
        averaged one within ``min_deviation`` and :meth:`.PlantGain.fault_possible` allows
        the average: a product still moving (a valve's overlap takes it towards 0 at each
        reversal, where the spool moves and no oil flows) is no sensor gain yet, and reading a
        sound sensor through it costs more than waiting."""
        if theta < self._failed_below:
            self.flow_fault = False
            return
        if self.window.w < self._min_evidence:
            return
        was = self.flow_fault or self.sensor_decided
        if self.flow_fault:
            self.flow_fault = self.llr > -self._on
        else:
            kb, beside = self.k_base, self._beside
            avg = self._avg
            self.flow_fault = (
                self.llr > self._on
                and abs(theta / beside - kb) >= self._min_dev * kb
                and avg.mean - avg.reach >= self._failed_below
            )
            if self.flow_fault:  # H_Q beside the sensor gain H_D stood at (1: the deviation's own)
                self._s = beside
        if self.flow_fault:
            self.sensor_decided = False
        elif (
            self.llr < -self._on_d
            and abs(theta - self._avg.mean) < self._min_dev * self.k_base
            and self.plant.fault_possible(self._avg.mean)
        ):
            self.sensor_decided = self.sensor_current = True
            self._s = self._avg.mean / self.k_base  # the averaged product: one θ_pos wanders
            self._s_held = False
            self._by_test = True
        if (self.flow_fault or self.sensor_decided) and not was:
            self._theta_ref = theta
