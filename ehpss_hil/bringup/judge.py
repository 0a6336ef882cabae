"""What a bring-up record says: sensors present, spool null and sensor zero, the echo's, the
spool's and the piston's polarity. Pure functions over the record (SI units).

Expectations come from the params (the model the controller will run on): a current I held for
T moves the spool K_sv·I (``valve_static_gain_m_per_a``) and the piston about K_c·K_sv·I·T
(``velocity_gain_1_s``). A step counts as a motion when it reaches :data:`MOTION_SHARE` of that
(the model may be off by far less; a valve with its hydraulics off moves the spool only), and
its sign says the polarity. Both signs together name what is reversed:

==========  ==========  =============================================================
spool       piston      finding
==========  ==========  =============================================================
\\+          \\+          polarity as expected
−           −           the valve's drive (coil or amplifier polarity)
−           \\+          the spool LVDT
\\+          −           the piston position sensor
==========  ==========  =============================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..physics.params import PlantParams
from .sequence import BringupController

#: a step must move spool and piston at least this share of what the params expect
MOTION_SHARE = 0.25
#: the spool may rest at most this share of its stroke off centre at 0 A (its null offset)
NULL_SHARE = 0.05
#: the current echo must agree with the command within this share of it
ECHO_SHARE = 0.5
#: at least this share of the sequence's sensor samples must arrive
MIN_SAMPLES_SHARE = 0.9
#: the first share of a step phase is left out of the spool's steady value (its rise, ~10 ms)
SETTLING_SHARE = 0.5


@dataclass(frozen=True)
class Finding:
    """One check: its name, whether it passed, and one line saying what was measured."""

    name: str
    ok: bool
    text: str


def _mean(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(x.mean()) if len(x) else math.nan


def _um(x: float) -> str:
    return f"{x * 1e6:+.1f} µm"


def _motion(delta: float, expected: float) -> int:
    """+1 / −1: moved that way by at least MOTION_SHARE of ``expected`` (> 0); 0: did not."""
    if not math.isfinite(delta) or abs(delta) < MOTION_SHARE * expected:
        return 0
    return 1 if delta > 0 else -1


def judge(ctrl: BringupController, plant: PlantParams) -> list[Finding]:
    """Every finding of the record of ``ctrl`` against the model ``plant`` (module docstring)."""
    rows, (rest, plus, _, _) = ctrl.rows, ctrl.bounds
    got = int(np.isfinite(rows[:, 0]).sum())
    out = [
        Finding(
            "sensors",
            got >= MIN_SAMPLES_SHARE * len(rows),
            f"{got} of {len(rows)} sensor samples arrived"
            + (
                ""
                if got >= MIN_SAMPLES_SHARE * len(rows)
                else " (a watchdog fail-safe stops them: see the summary)"
            ),
        )
    ]
    if not out[0].ok or ctrl.reason:
        return out + ([Finding("limits", False, ctrl.reason)] if ctrl.reason else [])
    spool0, pos0 = _mean(rows[:rest, 1]), _mean(rows[:rest, 0])
    noise = float(np.nanstd(rows[:rest, 0]))
    null_ok = abs(spool0) <= NULL_SHARE * plant.spool_stroke_m
    out.append(
        Finding(
            "zero",
            null_ok,
            f"at 0 A: position {pos0 * 1e3:+.4f} mm (noise {noise * 1e6:.1f} µm RMS), spool null "
            f"{_um(spool0)} (limit ±{NULL_SHARE * plant.spool_stroke_m * 1e6:g} µm)",
        )
    )
    i = ctrl.current_a
    settled = rest + int(SETTLING_SHARE * (plus - rest))
    echo = _mean(rows[rest + 1 : plus, 2])
    echo_ok = math.isfinite(echo) and abs(echo - i) <= ECHO_SHARE * i
    out.append(
        Finding(
            "echo",
            echo_ok,
            f"+{i * 1e6:.1f} µA commanded, the valve reports {echo * 1e6:+.1f} µA applied"
            + ("" if echo_ok else " (reversed)" if echo < 0 else " (not what was commanded)"),
        )
    )
    exp_spool = plant.valve_static_gain_m_per_a * i
    exp_travel = plant.velocity_gain_1_s * exp_spool * (plus - rest) * ctrl.ts_s
    d_spool = _mean(rows[settled:plus, 1]) - spool0
    end = rows[plus - 5 : plus, 0]
    d_pos = _mean(end) - pos0
    out.append(_polarity(_motion(d_spool, exp_spool), _motion(d_pos, exp_travel), d_spool, d_pos, i))
    return out


def _polarity(spool: int, piston: int, d_spool: float, d_pos: float, i: float) -> Finding:
    """The polarity finding from the signs of the spool's and the piston's motion."""
    moved = f"+{i * 1e6:.1f} µA moved the spool {_um(d_spool)} and the piston {_um(d_pos)}"
    if spool == 0 or piston == 0:
        what = "the spool" if spool == 0 else "the piston"
        return Finding(
            "polarity", False, f"{what} did not move: {moved} (hydraulics, amplifier enable, sensor?)"
        )
    verdict = {
        (1, 1): "",
        (-1, -1): "the valve's drive is reversed (coil or amplifier polarity)",
        (-1, 1): "the spool position (LVDT) reads reversed",
        (1, -1): "the piston position sensor reads reversed",
    }[spool, piston]
    return Finding("polarity", not verdict, f"{verdict}: {moved}" if verdict else f"as expected: {moved}")
