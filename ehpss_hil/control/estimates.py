"""The one owner of mmac's estimator state: x̂, the seed point (x0, y0) and k̂_LOE, k̂_DFT, k̂_Q.

The position channel regresses ``y_s − y0`` on ``x̂ − x0``: offset-free whatever k_DFT was when
the seed was taken. ``x0 = y0/θ`` with θ = θ̂_D·k̂_Q in use keeps x̂ the absolute position as the
estimates move (:meth:`Estimates.rebase`). Every change of this state that evidence decides —
seeding, re-basing, re-anchoring on a trusted sensor, placing x̂ where the spool took the piston
when the sensor is found dead, entering and leaving the flow-gain hypothesis, restarting the
position channel — is one method here, and nothing else assigns ``x̂.x``, x0 or y0. (The sample
clock, :mod:`.sampleclock`, *advances* x̂ on the spool every sample and starts it on the first
sample after a reset; that is the predictor's own motion, not a decision.)

The k̂ are what the loop compensates with (:class:`~.controllers.LoopBase` reads them as
``k_loe_hat``/``k_dft_hat``/``k_q_hat``; the controller publishes them once per sample):
``k_loe`` is the current divisor k̂_LOE·k̂_Q, ``k_dft`` the sensor gain, ``k_q`` the flow gain.
Units: positions in m, gains dimensionless.
"""

from __future__ import annotations

from .predictors import ModelPosition


class Estimates:
    """x̂ (a :class:`ModelPosition`), x0, y0 (m) and the k̂ in use, changed only by the methods."""

    __slots__ = (
        "_failed_below",
        "_kq_dead",
        "_rebase_limit_m",
        "k_dft",
        "k_loe",
        "k_q",
        "theta_d",
        "x0",
        "xhat",
        "y0",
    )

    def __init__(self, xhat: ModelPosition, failed_below: float, rebase_limit_m: float) -> None:
        """``xhat``: the model position the sample clock advances; ``failed_below``: θ of the
        failed-sensor model (``sensor_failed_below``); ``rebase_limit_m``: the largest re-base of
        x̂ at once (m, ``rebase_limit`` reference amplitudes)."""
        self.xhat = xhat
        self._failed_below = failed_below
        self._rebase_limit_m = rebase_limit_m
        self.reset()

    def reset(self) -> None:
        """Nominal gains, seed point at 0 (x̂ itself is reset by its owner, the loop)."""
        #: the seed point: the sensor (m) and x̂ (m) at the first sample after the reset
        self.y0 = self.x0 = 0.0
        self.k_loe = self.k_dft = self.k_q = 1.0
        #: the position bank's gain in use (k_DFT times the plant's flow gain k_base)
        self.theta_d = 1.0
        #: the flow gain attributed when the sensor was found dead: x̂ goes on at it (1: none)
        self._kq_dead = 1.0

    def seed(self, position_m: float) -> None:
        """x̂ = y_s now, as if k_DFT were 1: only differences from here are used."""
        self.xhat.x = self.y0 = self.x0 = position_m

    def set_creep(self, rate_m_s: float) -> None:
        """x̂ moves with the creep, in its own units (m/s of x/k̂_Q: the sensor read through θ_prod)."""
        self.xhat.creep_m_s = rate_m_s

    def set_band_gain(self, gain: float) -> None:
        """x̂ integrates ``gain`` times a spool inside the overlap band (the overlap shown)."""
        self.xhat.band_gain = gain

    def set_channels(self, k_loe: float, k_dft: float, trusted: bool, k_base: float = 1.0) -> None:
        """The banks' estimates in use (spool channel, position channel), k̂_Q back to 1 (to the
        flow gain kept by :meth:`place_dead` while the sensor is dead), and x̂ re-based on the
        sensor gain (:meth:`rebase`, while the sensor is ``trusted``)."""
        kq = self._kq_dead if self._kq_dead != 1.0 else k_base
        self.k_loe = k_loe * kq
        self.theta_d = k_dft
        self.k_dft = k_dft / k_base
        self.k_q = kq
        if trusted:  # rebase(k_dft, True), spelled out: this runs on every sample
            x0 = self.y0 / k_dft
            if not abs(x0 - self.x0) > self._rebase_limit_m:
                self.xhat.x += x0 - self.x0
                self.x0 = x0

    def reanchor(self, position_m: float, x_hat_m: float) -> None:
        """Start the position regression over from the trusted sensor at ``position_m`` with x̂
        at ``x_hat_m`` (a dead-reckoned offset is no drift), then re-base on θ̂_D."""
        self.y0, self.x0 = position_m, x_hat_m

    def place_dead(self, position_m: float, x_dead_m: float, k_q: float = 1.0) -> None:
        """The sensor stood still through a stop phase: x̂ where the spool took the piston, and
        the regression from here (a stuck reading then fits the failed-sensor model). ``k_q``:
        the flow gain attributed before (x̂ is in x/k̂_Q units); x̂ goes on at it, and it stays
        k̂_Q until :meth:`revive`."""
        self.xhat.x = x_dead_m
        self.y0, self.x0 = position_m, x_dead_m
        self._kq_dead = k_q

    def revive(self) -> None:
        """The sensor found dead follows the spool again: x̂ and x0 from x/k̂_Q units into the
        piston's, k̂_Q back to 1."""
        kq = self._kq_dead
        if kq != 1.0:
            self.xhat.x *= kq
            self.x0 *= kq
            self._kq_dead = 1.0

    def pivot_to_zero(self, theta: float) -> None:
        """The increments confirm θ = θ̂_D (the reading is θ·x now, offset-free): if x̂ is
        re-based on it (x0 = y0/θ), the regression goes through the sensor's zero from here,
        x̂ unchanged. A pivot away from the zero would read a later change of the sensor's
        gain, which scales the reading about its zero, as an offset of (gain change × pivot)."""
        if self.x0 == self.y0 / theta:
            self.y0 = self.x0 = 0.0

    def rebased_x(self, theta: float) -> float:
        """x̂ (m) as a re-base on the gain ``theta`` would place it, without re-basing."""
        return self.xhat.x + self.y0 / theta - self.x0

    def rebase(self, theta: float, trusted: bool) -> None:
        """Keep x0 = y0/θ with θ = θ̂_D·k̂_Q in use: x̂ moves with x0 (x̂ − x0 is unchanged), so
        it stays the absolute position while the sensor gain estimate changes. Not while the
        sensor is not ``trusted`` (failed, held off, guarded), nor by more than the re-base
        limit at once: a model that would put x̂ that far away does not describe the sensor."""
        if trusted:
            x0 = self.y0 / theta
            if abs(x0 - self.x0) > self._rebase_limit_m:
                return
            self.xhat.x += x0 - self.x0
            self.x0 = x0

    def enter_flow(self, position_m: float, prod: float, k_loe: float, sensor: float = 1.0) -> None:
        """Under H_Q (a flow-gain change): the sensor at the gain H_D was last decided at
        (``sensor``, 1: healthy), k̂_Q the product less it, the current divided by k̂_LOE·k̂_Q, and
        x̂ (in x/k̂_Q units) kept on the sensor so that nothing jumps when the test returns to
        H_D."""
        kq = prod / sensor
        self.k_q = kq
        self.k_loe = k_loe * kq
        self.k_dft = sensor
        self.xhat.x = position_m / prod
        self.x0 = self.y0 / prod if prod >= self._failed_below else self.x0

    def leave_flow(self, position_m: float, prod: float) -> None:
        """Back to H_D: the product is the sensor's gain (≈ 1 when the deviation vanished); x̂
        and x0 read through it (the caller then seeds the position bank with it)."""
        live = prod >= self._failed_below
        self.xhat.x = position_m / prod if live else position_m
        self.x0 = self.y0 / prod if live else self.y0

    def set_sensor_gain(self, theta_d: float, k_base: float = 1.0) -> None:
        """The position model in use after the bank was re-seeded: its gain ``theta_d`` is the
        sensor's times the plant's flow gain ``k_base``."""
        self.theta_d = theta_d
        self.k_dft = theta_d / k_base

    def restart(self, position_m: float) -> None:
        """The plant model changed under the position channel: x̂ = y_s, nominal k̂_Q."""
        self.xhat.x = position_m
        self.y0 = self.x0 = position_m
        self.k_q = 1.0
