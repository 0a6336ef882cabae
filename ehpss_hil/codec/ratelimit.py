"""Rate plausibility of a position reading: how far it may move between two samples.

A frame that passes E2E can still carry a value no sensor produced: about 1 in 3400 random
payloads passes the 8-bit CRC and the 4-bit counter check, and a second transmitter's frames
pass whenever their counter happens to fit. Their Position is spread over the DBC range (±0.5 m)
while the piston's moves ~33 µm per millisecond at most, so the jump from the previous reading
tells most of them apart. The bound must pass what a real sensor does:

- motion: the fastest piston (``speed_max_m_s``: K_c × spool stroke, ≈ 33 mm/s) read through a
  sensor gain k_DFT of up to :data:`K_DFT_MAX`, with a margin :data:`SPEED_MARGIN`, times the
  samples elapsed since the reference reading (from the E2E counters, 1…16);
- a sensor gain step (a drift event, a failure to 0): from k·x to k'·x with k, k' in
  [0, K_DFT_MAX] and k ≈ 1 before, a jump of up to :data:`GAIN_JUMP` × the previous reading —
  a failed sensor's jump to 0 always passes;
- anything else (a bias step, a gain step from an already drifted gain): two consecutive
  readings that agree with each other are a new level; the first of them is rejected, the
  second accepted (one sample lost, like a lost frame). Consecutive: no frame of the ID in
  between, not even one that failed the sequence check (:meth:`RateLimit.interrupt`), so a
  second transmitter whose frames alternate with the sensor's never sets a level.

So a random reading passes with probability ≈ 2·(n·step + 1.5·|y|) / 1 m: about 1 in 3 for a
piston at 0.1 m, 1 in 250 at 1 mm (with the 1-in-3400 E2E chance: 1 in 850 000 random frames).
"""

from __future__ import annotations

from .e2e import counter_steps

#: the largest sensor gain k_DFT a scenario or an injected fault may set (scenario.FaultEvent)
K_DFT_MAX = 2.5
#: margin over the fastest reading's rate (the plant's speed bound is a steady-state figure)
SPEED_MARGIN = 2.0
#: a gain step from k ≈ 1 to anything in [0, K_DFT_MAX] moves a reading by at most this × it
GAIN_JUMP = K_DFT_MAX - 1.0


def position_step_bound_m(speed_max_m_s: float, ts_s: float) -> float:
    """The largest plausible change of a position reading in one sample period (m): the
    fastest piston (m/s) over ``ts_s`` (s), through k_DFT up to :data:`K_DFT_MAX`, with
    :data:`SPEED_MARGIN`."""
    return speed_max_m_s * ts_s * K_DFT_MAX * SPEED_MARGIN


class RateLimit:
    """The rate check of one signal of one E2E-protected frame ID (see the module docstring):
    :meth:`check` per frame that passed E2E and the range check."""

    __slots__ = ("_anchor", "_anchor_counter", "_candidate", "_candidate_counter", "rejected", "step_m")

    def __init__(self, step_m: float) -> None:
        """``step_m``: the largest plausible change per sample period (m)."""
        self.step_m = step_m
        self.rejected = 0
        self.reset()

    def reset(self) -> None:
        """Forget the reference reading (the next one is accepted)."""
        self._anchor: float | None = None
        self._anchor_counter = 0
        self._candidate: float | None = None
        self._candidate_counter = 0

    def interrupt(self) -> None:
        """A frame of the ID failed the sequence check: the next reading does not follow the
        rejected one."""
        self._candidate = None

    def _near(self, value: float, ref: float, samples: int) -> bool:
        return abs(value - ref) <= samples * self.step_m + GAIN_JUMP * abs(ref)

    def check(self, value: float, counter: int) -> bool:
        """True when ``value`` (m; E2E counter ``counter``) is a plausible next reading; it then
        becomes the reference. A rejected one is remembered: the next reading close to it is
        accepted (a new level)."""
        anchor, cand = self._anchor, self._candidate
        ok = (
            anchor is None
            or self._near(value, anchor, counter_steps(counter, self._anchor_counter))
            or (cand is not None and self._near(value, cand, counter_steps(counter, self._candidate_counter)))
        )
        if ok:
            self._anchor, self._anchor_counter, self._candidate = value, counter, None
        else:
            self._candidate, self._candidate_counter = value, counter
            self.rejected += 1
        return ok
