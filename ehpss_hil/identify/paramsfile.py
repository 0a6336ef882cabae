"""Write an identification result as a params file in ``params.yaml``'s format (the one
:func:`~ehpss_hil.physics.load.load_params` reads): every plant key (the fitted ones with
their 95 % interval as a comment) and the controller gains of the start params."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from ..errors import OutputError
from .fit import FitResult


def params_text(result: FitResult, source: str) -> str:
    """The file's text (YAML with comments)."""
    fitted = {e.name: e for e in result.keys}
    p = result.params
    lines = [
        f"# Identified by `ehpss-hil identify` from {source}; 95 % intervals in the comments.",
        "# Keys without an interval (mass, area, stroke) and the controller gains are the start params'.",
        f"# spool null offset {result.spool_null_offset_m.value:.3g} m, position sensor zero "
        f"{result.position_zero_m.value:.3g} m (fitted, not params.yaml keys).",
        "plant:",
    ]
    for f in dataclasses.fields(p.plant):
        value = getattr(p.plant, f.name)
        e = fitted.get(f.name)
        note = f"  # ±{100 * e.rel_ci95:.2f} %" if e is not None else ""
        lines.append(f"  {f.name}: {value!r}{note}")
    lines.append("controller:")
    lines += [f"  {f.name}: {getattr(p.controller, f.name)!r}" for f in dataclasses.fields(p.controller)]
    return "\n".join(lines) + "\n"


def write_params(path: Path, result: FitResult, source: str) -> None:
    """Write the params file atomically (a temporary file beside it, then renamed)."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(params_text(result, source))
        os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
