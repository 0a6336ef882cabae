"""Fault compensation (DESIGN §5 step 6): divide the faults out, bumplessly.

* feedback ``y_f = K_f·y_s/θ̂_D`` while the sensor is trusted, else ``K_f·x̂`` (model position);
* current ``I = u_PI/θ̂_L``.

Bumpless: the PI state z is never touched at a switch. The PI output u (the spool demand in
ampere-equivalents of a healthy valve) is continuous as long as the feedback is; only the
division by θ̂_L changes the current, which is the compensation itself (the actual spool
``k_LOE·I`` stays continuous when θ̂_L is right).
"""

from __future__ import annotations

#: smallest θ̂_L the current is divided by (matches the estimator's lower clip)
MIN_THETA_L = 0.05


def sensor_trusted(theta_d: float, failed_below: float, guarded: bool, fresh: bool) -> bool:
    """True when the position sensor may be fed back (not declared failed, explained, fresh)."""
    return fresh and not guarded and theta_d >= failed_below


def feedback_signal(  # the plain form; LoopBase._close adds the bumpless blend and x̂ scaling
k_f: float, position_m: float, theta_d: float, model_position_m: float,
                    trusted: bool) -> float:
    """The fed-back position in sensor units (K_f·m)."""
    if trusted:
        return k_f * position_m / theta_d
    return k_f * model_position_m


def compensated_current(pi_output_a: float, theta_l: float) -> float:
    """Coil current (A) that makes the faulty valve produce the healthy valve's spool."""
    return pi_output_a / (theta_l if theta_l > MIN_THETA_L else MIN_THETA_L)
