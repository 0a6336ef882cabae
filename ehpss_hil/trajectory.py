"""Reference trajectories from CSV files (``reference: {kind: file, path: …}``).

The file is read once, when the config or scenario naming it is loaded (never inside the control
loop): a regular file of at most :data:`~ehpss_hil.limits.MAX_REFERENCE_BYTES`, rows ``t_s,x_m``
(``#`` comments allowed), two finite columns, strictly increasing time, |x| within the DBC's
position range, at most :data:`~ehpss_hil.limits.MAX_REFERENCE_ROWS` rows. The table stays in
memory; x_d(t) is interpolated linearly from it and held after the last row.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ConfigError
from .inputfile import decode_text, read_capped
from .limits import MAX_REFERENCE_BYTES, MAX_REFERENCE_M, MAX_REFERENCE_ROWS


class ReferenceTable:
    """An immutable trajectory: times ``t_s`` (s, strictly increasing) and positions ``x_m``
    (m). Copying returns the same object (it is never changed)."""

    __slots__ = ("path", "t_s", "x_m")

    def __init__(self, t_s: np.ndarray, x_m: np.ndarray, path: str = "") -> None:
        self.t_s = np.array(t_s, dtype=np.float64)
        self.x_m = np.array(x_m, dtype=np.float64)
        self.t_s.setflags(write=False)
        self.x_m.setflags(write=False)
        self.path = path

    def sample(self, t_s: np.ndarray) -> np.ndarray:
        """x_d at the times ``t_s`` (m): linear interpolation, the end values held outside."""
        return np.interp(t_s, self.t_s, self.x_m)

    def __len__(self) -> int:
        return len(self.t_s)

    def __deepcopy__(self, memo: dict[int, Any]) -> ReferenceTable:
        return self

    def __repr__(self) -> str:
        return f"ReferenceTable({len(self)} rows from {self.path})"


def _check(data: np.ndarray) -> str | None:
    """What is wrong with a parsed table, or None."""
    if data.size == 0:
        return "no rows"
    if data.shape[1] != 2:
        return f"expected two columns t_s,x_m, got {data.shape[1]}"
    if len(data) > MAX_REFERENCE_ROWS:
        return f"more than {MAX_REFERENCE_ROWS} rows"
    bad = np.flatnonzero(~np.isfinite(data).all(axis=1))
    if bad.size:
        return f"row {bad[0] + 1}: not a finite number"
    if len(data) > 1:
        back = np.flatnonzero(np.diff(data[:, 0]) <= 0.0)
        if back.size:
            return f"row {back[0] + 2}: time must increase (t_s {data[back[0] + 1, 0]:g})"
    far = np.flatnonzero(np.abs(data[:, 1]) > MAX_REFERENCE_M)
    if far.size:
        return f"row {far[0] + 1}: |x_m| above {MAX_REFERENCE_M} m"
    return None


def load_reference_table(path: str | Path, source: str = "", key: str = "reference.path") -> ReferenceTable:
    """Read and validate the trajectory CSV ``path``; errors are ConfigError for ``key`` in the
    file ``source`` (the config or scenario naming it)."""
    src = source or str(path)
    where = f"{path}: "
    try:
        text = decode_text(read_capped(path, MAX_REFERENCE_BYTES, key), src, key)
    except ConfigError as exc:
        raise ConfigError(src, key, f"{where}{exc.reason}") from exc
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": reported below
            data = np.loadtxt(
                io.StringIO(text), delimiter=",", ndmin=2, dtype=np.float64, max_rows=MAX_REFERENCE_ROWS + 1
            )
    except ValueError as exc:
        raise ConfigError(src, key, f"{where}not a CSV of numbers t_s,x_m ({exc})") from exc
    problem = _check(data)
    if problem is not None:
        raise ConfigError(src, key, f"{where}{problem}")
    return ReferenceTable(data[:, 0], data[:, 1], str(path))
