"""The matrix exponential by scaling and squaring with Padé approximants, in numpy alone.

The models here are 2 to 7 states, so this is the whole of what the daemon needs from
``scipy.linalg.expm`` (which would cost the daemon scipy's import at start-up). The method is
Higham's (N. J. Higham, "The scaling and squaring method for the matrix exponential revisited",
SIAM J. Matrix Anal. Appl. 26(4), 2005, Algorithm 2.3): the Padé degree m ∈ {3, 5, 7, 9, 13}
is the lowest whose backward-error bound θ_m covers ‖A‖₁; beyond θ₁₃ the matrix is scaled by
2⁻ˢ so that ‖A/2ˢ‖₁ ≤ θ₁₃, and the result squared s times. ``tests/test_physics_expm.py``
compares it with ``scipy.linalg.expm`` over the parameters' range.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

Matrix = NDArray[np.float64]

#: Padé coefficients b_0..b_m of degree m (Higham 2005, Table 2.3 / eq. 2.5)
_PADE: dict[int, tuple[float, ...]] = {
    3: (120.0, 60.0, 12.0, 1.0),
    5: (30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0),
    7: (17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0),
    9: (
        17643225600.0,
        8821612800.0,
        2075673600.0,
        302702400.0,
        30270240.0,
        2162160.0,
        110880.0,
        3960.0,
        90.0,
        1.0,
    ),
    13: (
        64764752532480000.0,
        32382376266240000.0,
        7771770303897600.0,
        1187353796428800.0,
        129060195264000.0,
        10559470521600.0,
        670442572800.0,
        33522128640.0,
        1323241920.0,
        40840800.0,
        960960.0,
        16380.0,
        182.0,
        1.0,
    ),
}

#: θ_m of Al-Mohy and Higham (2009), Table 3.1: the largest η for which degree m meets double
#: precision's backward error (θ₁₃ = 4.25 with their sharper bounds)
_THETA = {3: 1.495585217958292e-2, 5: 2.539398330063230e-1, 7: 9.504178996162932e-1, 9: 2.097847961257068}
_THETA_13 = 4.25
#: unit roundoff of float64
_U = 2.0**-53


def expm(a: Matrix) -> Matrix:
    """``exp(A)`` of a square real matrix (dimensionless: the caller multiplies by the time)."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"expm needs a square matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("expm needs a finite matrix")
    if a.size == 0:
        return a.copy()
    a2 = a @ a
    a4 = a2 @ a2
    a6 = a2 @ a4
    d4, d6 = _onenorm(a4) ** 0.25, _onenorm(a6) ** (1 / 6)
    eta1 = max(d4, d6)
    for m in (3, 5):
        if eta1 <= _THETA[m] and _ell(a, m) == 0:
            return _pade_solve(*_pade_low(a, a2, m))
    a8 = a4 @ a4
    d8 = _onenorm(a8) ** 0.125
    eta3 = max(d6, d8)
    for m in (7, 9):
        if eta3 <= _THETA[m] and _ell(a, m) == 0:
            return _pade_solve(*_pade_low(a, a2, m))
    d10 = _onenorm(a4 @ a6) ** 0.1
    eta5 = min(eta3, max(d8, d10))
    s = max(0, math.ceil(math.log2(eta5 / _THETA_13))) if eta5 > 0 else 0
    s += _ell(a / 2.0**s, 13)
    r = _pade_solve(*_pade13(a / 2.0**s))
    for _ in range(s):
        r = r @ r
    return r


def _onenorm(a: Matrix) -> float:
    """‖A‖₁: the largest column sum of magnitudes."""
    return float(np.abs(a).sum(axis=0).max())


def _ell(a: Matrix, m: int) -> int:
    """Al-Mohy and Higham's ℓ(A, m) (2009, eq. 5.3 with exact norms): how many extra squarings
    keep the degree-m approximant's truncation error below the unit roundoff for a matrix whose
    ‖A‖₁ overstates its powers (badly scaled, non-normal matrices such as the plant's)."""
    p = 2 * m + 1
    norm_a = _onenorm(a)
    if norm_a == 0.0:
        return 0
    col = np.abs(a).sum(axis=0)  # 1ᵀ|A|; then 1ᵀ|A|^k, whose largest entry is ‖|A|^k‖₁
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(p - 1):
            col = col @ np.abs(a)
        power_norm = float(col.max())
    if not math.isfinite(power_norm):
        return 1 << 10  # no finite bound: the caller scales (only reached for m = 13 with s = 0)
    recip_c = math.factorial(2 * m) * math.factorial(2 * m + 1) / math.factorial(m) ** 2
    alpha = power_norm / (norm_a * recip_c)
    if alpha == 0.0:
        return 0
    return max(0, math.ceil(math.log2(alpha / _U) / (2 * m)))


def _pade_low(a: Matrix, a2: Matrix, m: int) -> tuple[Matrix, Matrix]:
    """(U, V) of the degree-m Padé approximant, m ∈ {3, 5, 7, 9} (``a2`` is A²)."""
    b = _PADE[m]
    ident = np.eye(a.shape[0])
    powers = [ident, a2]
    for _ in range(2, m // 2 + 1):
        powers.append(powers[-1] @ a2)
    u = a @ sum((b[2 * k + 1] * powers[k] for k in range(m // 2 + 1)), np.zeros_like(a))
    v = sum((b[2 * k] * powers[k] for k in range(m // 2 + 1)), np.zeros_like(a))
    return u, v


def _pade13(a: Matrix) -> tuple[Matrix, Matrix]:
    """(U, V) of the degree-13 Padé approximant with Higham's 6 matrix products."""
    b = _PADE[13]
    ident = np.eye(a.shape[0])
    a2 = a @ a
    a4 = a2 @ a2
    a6 = a2 @ a4
    u = a @ (a6 @ (b[13] * a6 + b[11] * a4 + b[9] * a2) + b[7] * a6 + b[5] * a4 + b[3] * a2 + b[1] * ident)
    v = a6 @ (b[12] * a6 + b[10] * a4 + b[8] * a2) + b[6] * a6 + b[4] * a4 + b[2] * a2 + b[0] * ident
    return u, v


def _pade_solve(u: Matrix, v: Matrix) -> Matrix:
    """r_m(A) = (V − U)⁻¹ (V + U), evaluated as I + 2 U (V − U)⁻¹ (U and V commute, being
    polynomials in A), as scipy does: for the plant's badly scaled matrices (V − U has condition
    numbers of 1e9 and more) the correction to I carries the rounding instead of the whole result,
    and dividing from the right keeps the row scaling of A out of the pivoting (about 1e3 times
    closer to the exact result than ``solve(V − U, V + U)`` for the closed loop at 1 kHz)."""
    correction = np.linalg.solve((v - u).T, u.T).T
    out: Matrix = np.eye(u.shape[0]) + 2.0 * correction
    return out
