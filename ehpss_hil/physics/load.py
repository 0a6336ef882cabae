"""Loading a params file and checking it against the model: the step after both
:mod:`.params` (the dataclasses) and :mod:`.model` (the eq-39 matrices built from them)."""

from __future__ import annotations

from pathlib import Path

from ..errors import ConfigError
from ..schema import build, load_yaml
from .params import DEFAULT_PARAMS, Params


def check_closed_loop_stable(params: Params, source: str = "") -> Params:
    """``params`` when the fault-free closed loop (eq 39) is stable: its reference model y_m and
    the simulated plant diverge otherwise (an integrator at rest, K_i = 0, is accepted).
    ConfigError naming ``source`` and the ``controller`` section otherwise."""
    import numpy as np

    from .model import closed_loop_matrices

    poles = np.linalg.eigvals(closed_loop_matrices(params)[0])
    worst = poles[np.argmax(poles.real)]
    if not np.isfinite(poles).all() or worst.real > 1e-9 * max(1.0, float(abs(poles).max())):
        raise ConfigError(
            source,
            "controller",
            "the fault-free closed loop (eq 39) with these "
            f"plant and gain values is unstable (pole at {worst:.4g} 1/s)",
        )
    return params


def load_params(path: str | Path | None = None) -> Params:
    """Load parameters from YAML (default: the shipped :data:`~.params.DEFAULT_PARAMS`),
    checked by :func:`check_closed_loop_stable`."""
    p = Path(path) if path is not None else DEFAULT_PARAMS
    return check_closed_loop_stable(build(Params, load_yaml(p), str(p)), str(p))
