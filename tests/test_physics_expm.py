"""The numpy matrix exponential (physics/expm.py) against scipy.linalg.expm and a 60-digit
reference, over the models and sample times the configs allow."""

from __future__ import annotations

from decimal import Decimal, localcontext

import numpy as np
import pytest
import scipy.linalg

from ehpss_hil.limits import MAX_RATE_HZ, MIN_RATE_HZ
from ehpss_hil.physics import load_params
from ehpss_hil.physics.discretize import Matrix
from ehpss_hil.physics.expm import expm
from ehpss_hil.physics.model import closed_loop_matrices, plant_matrices, valve_matrices

PARAMS = load_params()
#: What the plant needs of its ZOH map: a relative error (of the largest entry) far below one
#: position LSB relative to the DBC's range (0.1 µm over ±0.5 m = 1e-7), with a factor 100 left
#: for errors that accumulate over the slowest mode's settling. Two Padé implementations on
#: different numpy/LAPACK builds differ by rounding times the 2^s of s squarings (measured up to
#: 2.4e-10 at 10 Hz, 2e-13 at 500 Hz, numpy 2.4/scipy 1.17): so the bound is the plant's, not a
#: build's rounding.
PLANT_ZOH_REL_ERR = 1e-9
#: "the same class as scipy": no more than this factor above scipy's own error against the exact
#: exponential, plus this many units of double rounding (where both are at the rounding floor)
CLASS_FACTOR = 4.0
ROUNDING_FLOOR = 64 * float(np.finfo(float).eps)
#: the fault factors' range (tuning limits: k_LOE in [0.05, 1.5], k_DFT in [0, 2.5]) and flow gains
K_LOE = (0.05, 0.2, 0.5, 1.0, 1.5)
K_DFT = (0.0, 0.1, 1.0, 2.5)
K_Q = (0.3, 1.0, 2.0)


def _augmented(a: Matrix, b: Matrix, ts_s: float) -> Matrix:
    """``[[A, B], [0, 0]]·Ts``: its exponential is the ZOH ``[[Ad, Bd], [0, I]]``."""
    n, m = a.shape[0], b.shape[1]
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = a
    aug[:n, n:] = b
    return aug * ts_s


def _models(ts_s: float) -> list[Matrix]:
    out = [_augmented(*valve_matrices(PARAMS.plant), ts_s)]
    for k_loe in K_LOE:
        for k_q in K_Q:
            out.append(_augmented(*plant_matrices(PARAMS.plant, k_loe, k_q), ts_s))
            for k_dft in K_DFT:
                a, b, _ = closed_loop_matrices(PARAMS, k_loe, k_dft, k_q)
                out.append(_augmented(a, b, ts_s))
    return out


def _rel_err(got: Matrix, want: Matrix) -> float:
    """Largest entry error relative to the largest entry (the entries span 1e-3 to 1e5)."""
    return float(np.abs(got - want).max() / np.abs(want).max())


def _exact(a: Matrix) -> Matrix:
    """exp(A) in 60-digit decimal arithmetic: scaled to ‖A‖ ≤ 0.01, 25 Taylor terms, squared."""
    n = a.shape[0]
    zero = Decimal(0)

    def mul(x: list[list[Decimal]], y: list[list[Decimal]]) -> list[list[Decimal]]:
        return [[sum((x[i][q] * y[q][j] for q in range(n)), zero) for j in range(n)] for i in range(n)]

    with localcontext() as ctx:
        ctx.prec = 60
        m = [[Decimal(float(x)) for x in row] for row in a]
        s, norm = 0, max(sum((abs(m[i][j]) for i in range(n)), zero) for j in range(n))
        while norm > Decimal("0.01"):
            norm /= 2
            s += 1
        m = [[x / 2**s for x in row] for row in m]
        r = [[Decimal(int(i == j)) for j in range(n)] for i in range(n)]
        term = [row[:] for row in r]
        for k in range(1, 26):
            term = [[x / k for x in row] for row in mul(term, m)]
            r = [[r[i][j] + term[i][j] for j in range(n)] for i in range(n)]
        for _ in range(s):
            r = mul(r, r)
        return np.array([[float(x) for x in row] for row in r])


@pytest.mark.parametrize("rate_hz", [500.0, 1000.0, 2000.0, 5000.0, MAX_RATE_HZ])
def test_expm_agrees_with_scipy_within_the_plants_need_at_the_daemon_rates(rate_hz: float) -> None:
    for aug in _models(1.0 / rate_hz):
        assert _rel_err(expm(aug), scipy.linalg.expm(aug)) < PLANT_ZOH_REL_ERR


@pytest.mark.parametrize("rate_hz", [MIN_RATE_HZ, 50.0, 100.0, 250.0, 1000.0])
def test_expm_is_as_close_to_exact_as_scipy_at_every_rate(rate_hz: float) -> None:
    """At low rates (Ts up to 0.1 s, ‖A·Ts‖₁ up to 4e7, 30 squarings) scipy itself is up to
    4e-10 off the exact exponential; this one is in the same class (checked on the six models
    where the two differ most): its worst error is no more than :data:`CLASS_FACTOR` times
    scipy's worst (or at the rounding floor), and within what the plant needs at every rate."""
    models = _models(1.0 / rate_hz)
    worst = sorted(models, key=lambda a: -_rel_err(expm(a), scipy.linalg.expm(a)))[:6]
    exact = [_exact(a) for a in worst]
    ours = max(_rel_err(expm(a), e) for a, e in zip(worst, exact, strict=True))
    theirs = max(_rel_err(scipy.linalg.expm(a), e) for a, e in zip(worst, exact, strict=True))
    assert ours <= max(CLASS_FACTOR * theirs, ROUNDING_FLOOR), (ours, theirs)
    assert ours < PLANT_ZOH_REL_ERR, ours


def test_small_and_structured_matrices_take_every_pade_degree() -> None:
    """Norms from 1e-4 to 1e3 (degrees 3 to 13, with and without squaring), a nilpotent, a
    rotation, the zero and the empty matrix."""
    rng = np.random.default_rng(7)
    for scale in (1e-4, 1e-2, 0.2, 0.8, 2.0, 5.0, 40.0, 1e3):
        for n in (1, 2, 5, 7):
            a = rng.standard_normal((n, n)) * scale / n
            assert _rel_err(expm(a), scipy.linalg.expm(a)) < 1e-12 * max(1.0, scale)
    np.testing.assert_allclose(expm(np.array([[0.0, 1.0], [0.0, 0.0]])), [[1.0, 1.0], [0.0, 1.0]], atol=1e-15)
    t = 0.7
    rot = expm(np.array([[0.0, -t], [t, 0.0]]))
    np.testing.assert_allclose(rot, [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]], atol=1e-15)
    np.testing.assert_array_equal(expm(np.zeros((3, 3))), np.eye(3))
    assert expm(np.zeros((0, 0))).shape == (0, 0)


_BAD = [np.zeros((2, 3)), np.array([[np.nan]]), np.array([[np.inf, 0.0], [0.0, 1.0]])]


@pytest.mark.parametrize("bad", _BAD)
def test_rejects_non_square_or_non_finite(bad: Matrix) -> None:
    with pytest.raises(ValueError):
        expm(bad)
