"""Keep OpenBLAS single-threaded in the simulator.

The plant steps with a 5×5 numpy matvec every sample. With OpenBLAS's default thread pool the
idle BLAS threads spin between those tiny calls: measured here, a run then burns ~2× its useful
CPU time and two campaign workers gain nothing from a second core (1.0× instead of 1.8×).
``OPENBLAS_NUM_THREADS=1`` fixes it but must be set before numpy loads; this does the same at run
time through the OpenBLAS libraries already loaded (the approach of ``threadpoolctl``, which is
not a dependency). Linux only; elsewhere it does nothing.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

_SYMBOLS = ("openblas_set_num_threads", "scipy_openblas_set_num_threads64_",
            "scipy_openblas_set_num_threads_64_", "scipy_openblas_set_num_threads",
            "openblas_set_num_threads64_")


def _loaded_openblas() -> list[str]:
    maps = Path("/proc/self/maps")
    if not maps.exists():
        return []
    libs = {line.split()[-1] for line in maps.read_text().splitlines()
            if "openblas" in line.lower() and line.rstrip().endswith(".so")}
    return sorted(libs)


def limit_blas_threads(n: int = 1) -> int:
    """Set every loaded OpenBLAS to ``n`` threads; returns how many libraries were set."""
    done = 0
    for path in _loaded_openblas():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for sym in _SYMBOLS:
            fn = getattr(lib, sym, None)
            if fn is not None:
                fn(ctypes.c_int(n))
                done += 1
                break
    return done
