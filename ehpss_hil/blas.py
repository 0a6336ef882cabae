"""One BLAS thread per process, at run time (``threadpoolctl``).

The plant and the predictors step with tiny numpy matvecs every sample. With OpenBLAS's default
thread pool the idle BLAS threads spin between those calls: a simulator run then burned ~2× its
useful CPU time and two campaign workers gained nothing from a second core. The programs also set
``OPENBLAS_NUM_THREADS`` before numpy loads (:func:`limit_blas_env`); :func:`limit_blas_threads`
limits the libraries a library user already loaded.
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_limits

#: environment set before numpy loads (a value the user set is kept)
BLAS_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def limit_blas_env() -> None:
    """One BLAS thread for this process and its children, unless the user chose otherwise; call
    before numpy loads (the programs' entry points do). Under a small address-space limit
    (``ulimit -v``) OpenBLAS's thread-pool start-up otherwise spun forever."""
    for k, v in BLAS_ENV.items():
        os.environ.setdefault(k, v)


def limit_blas_threads(n: int = 1) -> None:
    """Hold every loaded BLAS library to ``n`` threads for the rest of the process."""
    threadpool_limits(limits=n, user_api="blas")
