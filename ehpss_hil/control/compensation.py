"""Fault compensation (docs/design.md §5 step 6): divide the faults out, bumplessly.

* feedback ``y_f = K_f·y_s/θ̂_D`` while the sensor is trusted, else ``K_f·x̂`` (model position);
* current ``I = u_PI/θ̂_L``.

Bumpless: the PI state z is never touched at a switch. The PI output u (the spool demand in
ampere-equivalents of a healthy valve) is continuous as long as the feedback is; only the
division by θ̂_L changes the current, which is the compensation itself (the actual spool
``k_LOE·I`` stays continuous when θ̂_L is right).
"""

from __future__ import annotations


def sensor_trusted(theta_d: float, failed_below: float, guarded: bool, fresh: bool) -> bool:
    """True when the position sensor may be fed back (not declared failed, explained, fresh)."""
    return fresh and not guarded and theta_d >= failed_below


def compensated_current(pi_output_a: float, theta_l: float, min_theta_l: float) -> float:
    """Coil current (A) that makes the faulty valve produce the healthy valve's spool; θ̂_L is
    taken no smaller than ``min_theta_l`` (the estimator's lower clip, ``k_loe_limits[0]``)."""
    return pi_output_a / (theta_l if theta_l > min_theta_l else min_theta_l)
