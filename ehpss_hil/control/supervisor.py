"""The switching supervisor of one model bank (docs/design.md §5 step 5).

Switch from the active model to the argmin of J only when all of these hold:

* ``J_best < (1 − h)·J_active − margin`` with ``margin = (a1 + a2/λ)·max(ε0², κ·n)`` and ``n`` the
  bank's noise floor (hysteresis relative *and* absolute, so noise alone never switches);
* the dwell time has passed since the last switch, and the warm-up since reset;
* the two models' θ differ by more than ``min_theta_separation`` (no chatter between twins);
* the channel is excited: ``|φ|/S ≥ excitation_floor``;
* all of the above held for ``switch_confirm_s`` in a row with the same best model (one noisy
  sample makes a large instantaneous ε², never a lasting one).

On a switch to a fixed model the RIA is reinitialized to it (θ and index memory).

Guard: when even the best model's ``J`` exceeds ``J_max = (a1 + a2/λ)·ε_g²`` no model explains
the data; :attr:`guarded` stays True until the best J falls below ``guard_release·J_max``
(default J_max/4). With ``sustained_guard`` the test uses the best model's mean-square residual
over the index memory instead of J, ``(a1 + a2/λ)·min_k I_k/w`` (equal to J in steady state), so a
fault transient that the adaptive models learn within a few samples never trips it — used on the
spool channel, whose fallback (k_LOE = 1) is wrong during an LOE transient. The position channel
keeps the instantaneous test: its fallback (model-position feedback) is safe in a transient.
"""

from __future__ import annotations

from typing import Protocol

from .tuning import ControlTuning


class Bank(Protocol):
    """What the supervisor needs from a bank (see :mod:`ehpss_hil.control.bank`)."""

    n: int
    n_fixed: int
    j: list[float]

    def noise_floor(self) -> float: ...

    def separation(self, a: int, b: int) -> float: ...

    def reinit_ria(self, source: int) -> None: ...


class Supervisor:
    """Hysteresis/dwell/warm-up/separation/excitation switching plus a no-model-fits guard."""

    __slots__ = (
        "_cand",
        "_confirm",
        "_dwell",
        "_eps0sq",
        "_floor",
        "_h",
        "_jmax",
        "_k",
        "_kappa",
        "_last",
        "_release",
        "_sep",
        "_streak",
        "_sustained",
        "_warm",
        "_win",
        "active",
        "bank",
        "guarded",
        "initial",
        "switches",
    )

    def __init__(
        self,
        bank: Bank,
        tuning: ControlTuning,
        ts_s: float,
        guard_epsilon: float | None = None,
        initial: int = 0,
        sustained_guard: bool = False,
    ) -> None:
        self.bank = bank
        self.initial = initial
        self._dwell = round(tuning.dwell_s / ts_s)
        self._confirm = max(1, round(tuning.switch_confirm_s / ts_s))
        self._warm = round(tuning.warmup_s / ts_s)
        self._h = tuning.hysteresis
        self._eps0sq = tuning.epsilon0**2
        self._kappa = tuning.noise_margin_factor
        self._win = tuning.index_a1 + tuning.index_a2 / tuning.forgetting_1_s
        self._sep = tuning.min_theta_separation
        self._floor = tuning.excitation_floor
        self._jmax = (self._win * guard_epsilon**2) if guard_epsilon else float("inf")
        self._release = tuning.guard_release * self._jmax
        self._sustained = sustained_guard
        self.reset()

    def reset(self) -> None:
        """Back to the initial (nominal) model, no switches, not guarded."""
        self.active = self.initial
        self.switches = 0
        self.guarded = False
        self._k = 0
        self._last = -(10**9)
        self._cand = -1
        self._streak = 0

    @property
    def margin(self) -> float:
        """The absolute switching margin (a1 + a2/λ)·max(ε0², κ·n) now."""
        return self._win * max(self._eps0sq, self._kappa * self.bank.noise_floor())

    def update(self, excitation: float) -> int:
        """Decide after the bank scored this sample; ``excitation`` = |φ|/S. Returns the active."""
        k = self._k = self._k + 1
        bank = self.bank
        j = bank.j
        jb = min(j)
        g = (self._win * bank.noise_floor()) if self._sustained else jb
        if self.guarded:
            if g < self._release:
                self.guarded = False
        elif g > self._jmax:
            self.guarded = True
        act = self.active
        ja = j[act]
        if jb < ja and k >= self._warm and k - self._last >= self._dwell and excitation >= self._floor:
            best = j.index(jb)
            if bank.separation(best, act) > self._sep and jb < (1.0 - self._h) * ja - self.margin:
                self._streak = self._streak + 1 if best == self._cand else 1
                self._cand = best
                if self._streak >= self._confirm:
                    self._switch(best)
                return self.active
        self._streak = 0
        return self.active

    def force(self, model: int) -> None:
        """Make ``model`` active now (outside the switching rule; counts as a switch if new)."""
        if model != self.active:
            self._switch(model)

    def _switch(self, best: int) -> None:
        self._streak = 0
        self._cand = -1
        self.active = best
        self._last = self._k
        self.switches += 1
        if best < self.bank.n_fixed:
            self.bank.reinit_ria(best)
