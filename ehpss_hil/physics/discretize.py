"""Exact zero-order-hold discretization, cached by the values that change the dynamics.

Never Euler: the plant's eigenvalues reach |λ| ≈ 5e3 rad/s, so explicit Euler at 1 ms diverges.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable

import numpy as np
from numpy.typing import NDArray

from .expm import expm

Matrix = NDArray[np.float64]


def zoh(a: Matrix, b: Matrix, ts_s: float) -> tuple[Matrix, Matrix]:
    """Exact ZOH of ``ẋ = A x + B u`` over ``ts_s`` seconds via ``expm`` of the augmented matrix.

    ``expm([[A, B], [0, 0]]·Ts) = [[Ad, Bd], [0, I]]``.
    """
    n, m = a.shape[0], b.shape[1]
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = a
    aug[:n, n:] = b
    e = expm(aug * ts_s)
    return np.ascontiguousarray(e[:n, :n]), np.ascontiguousarray(e[:n, n:])


class ZohCache:
    """ZOH maps of a parametrized model, computed once per distinct key.

    ``build(key) -> (A, B)`` gives the continuous model for a key such as ``(k_loe, k_q)``.
    """

    def __init__(
        self, build: Callable[[Hashable], tuple[Matrix, Matrix]], ts_s: float, max_entries: int = 256
    ) -> None:
        self._build = build
        self.ts_s = ts_s
        self._max = max_entries
        self._cache: dict[Hashable, tuple[Matrix, Matrix]] = {}

    def get(self, key: Hashable) -> tuple[Matrix, Matrix]:
        """The discrete ``(Ad, Bd)`` for ``key``; computed on first use."""
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) >= self._max:
                self._cache.pop(next(iter(self._cache)))
            a, b = self._build(key)
            hit = zoh(a, b, self.ts_s)
            self._cache[key] = hit
        return hit

    def __len__(self) -> int:
        return len(self._cache)
