"""Continuous-time EHPSS models (docs/design.md §6), SI units.

State orders:

* plant ``s = [ẍ, ẋ, x, ẋ_v, x_v]`` — piston acceleration (m/s²), velocity (m/s), position (m),
  commanded-spool velocity (m/s), commanded-spool position (m); input: applied coil current (A).
* closed loop (paper eq 39) ``[ẍ, ẋ, x, ẋ_v, x_v, z]`` with the PI state ``z`` (controller units·s);
  input: desired position ``x_d`` (m); output: ``x`` (m).
* valve ``[ẋ_v, x_v]``; input: coil current (A).

The actual spool is ``k_loe·x_v`` (eq 8); the cylinder sees ``k_loe·k_q·x_v``; the position sensor
reads ``k_dft·x`` (eq 11).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .params import ControllerGains, Params, PlantParams

Matrix = NDArray[np.float64]

#: indices into the plant state vector
ACC, VEL, POS, SPOOL_VEL, SPOOL = 0, 1, 2, 3, 4


def valve_matrices(p: PlantParams) -> tuple[Matrix, Matrix]:
    """Servo valve (eq 7): state ``[ẋ_v, x_v]`` (m/s, m), input coil current (A)."""
    a = np.array([[-p.valve_damping_1_s, -p.valve_stiffness_1_s2], [1.0, 0.0]])
    b = np.array([[p.valve_gain_m_per_a_s2], [0.0]])
    return a, b


def plant_matrices(p: PlantParams, k_loe: float = 1.0, k_q: float = 1.0) -> tuple[Matrix, Matrix]:
    """Open-loop plant (eqs 7, 9): ``ṡ = A s + B I`` with ``s = [ẍ, ẋ, x, ẋ_v, x_v]``."""
    a = np.zeros((5, 5))
    a[ACC, ACC] = -p.cylinder_damping_1_s
    a[ACC, VEL] = -p.hydraulic_stiffness_1_s2
    a[ACC, SPOOL] = p.flow_gain_1_s3 * k_loe * k_q
    a[VEL, ACC] = 1.0
    a[POS, VEL] = 1.0
    av, bv = valve_matrices(p)
    a[3:5, 3:5] = av
    b = np.zeros((5, 1))
    b[3:5] = bv
    return a, b


def closed_loop_matrices(
    params: Params, k_loe: float = 1.0, k_dft: float = 1.0, k_q: float = 1.0
) -> tuple[Matrix, Matrix, Matrix]:
    """The paper's eq 39 closed loop (PI on the drifted sensor), corrected per docs/design.md §6.

    Returns ``(A, B, C)`` for state ``[ẍ, ẋ, x, ẋ_v, x_v, z]``, input ``x_d`` (m), output ``x`` (m).
    The PI is ``e = K_f·x_d − K_f·k_dft·x``, ``ż = K_i·e``, ``I = K_a·(K_p·e + K_i·z)``.
    """
    p, g = params.plant, params.controller
    ap, bp = plant_matrices(p, k_loe, k_q)
    a = np.zeros((6, 6))
    a[:5, :5] = ap
    gain_e = bp[:, 0] * g.k_a * g.k_p  # current per unit error, times plant input column
    # e = K_f x_d - K_f k_dft x
    a[:5, POS] += -gain_e * g.k_f * k_dft
    a[:5, 5] += bp[:, 0] * g.k_a * g.k_i
    a[5, POS] = -g.k_i * g.k_f * k_dft
    b = np.zeros((6, 1))
    b[:5, 0] = gain_e * g.k_f
    b[5, 0] = g.k_i * g.k_f
    c = np.zeros((1, 6))
    c[0, POS] = 1.0
    return a, b, c


def load_pressure_pa(p: PlantParams, acceleration_m_s2: float) -> float:
    """Load pressure from eq 4 with B_v = k = F_L = 0: ``P_L = m·ẍ/A_h`` (Pa)."""
    return p.load_mass_kg * acceleration_m_s2 / p.piston_area_m2


def pi_current_a(g: ControllerGains, error: float, integral: float) -> float:
    """Eq 39's PI + amplifier: ``I = K_a·(K_p·e + K_i·z)`` (A) for error/integral in sensor units."""
    return g.k_a * (g.k_p * error + g.k_i * integral)
