"""``bench resolution``: a rescaled DBC quantizes through its new factor, the limit derivation
reads the grid as documented, and the DBC with every signal at check-config's accepted limit
keeps mmac from harm and compensating on the paper's cases 1–3 (the promise the limits make)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ehpss_hil.bench.resolution import (
    ALL_AT_LIMITS,
    NATIVE,
    Row,
    accepted_limits,
    derived_limit,
    grid,
    harmless_limit,
    sweep,
)
from ehpss_hil.codec import FrameCodec
from ehpss_hil.protocol.logical import LOGICAL_SIGNALS
from ehpss_hil.sim.rescale import native_lsb, rescaled_dbc


def test_a_rescaled_dbc_quantizes_through_its_new_factor(tmp_path: Path) -> None:
    codec = FrameCodec(rescaled_dbc({"coil_current": 3e-6, "position": 2e-6}, tmp_path / "r.dbc"))
    aux = codec.quantize("SENSOR_AUX", {"CoilCurrent": 12.3457e-6})
    assert aux["CoilCurrent"] == pytest.approx(12e-6, abs=1e-15)  # 4 steps of 3 µA
    pos = codec.quantize("SENSOR_POS", {"Position": 1.2345e-3, "Spool": 1.2345e-3})
    assert pos["Position"] == pytest.approx(1.234e-3, abs=1e-15)
    assert pos["Spool"] == pytest.approx(1.2345e-3, abs=1e-9)  # native 2 nm, unchanged
    assert native_lsb("spool") == pytest.approx(2e-9)
    with pytest.raises(ValueError, match="does not fit"):
        rescaled_dbc({"position": 1e-9}, tmp_path / "fine.dbc")  # ±0.5 m in 24 bits: no


def _row(lsb: float, *faults: str) -> Row:
    return Row("coil_current", lsb, (), (tuple(faults),))


def test_the_derived_limit_stops_at_the_first_bad_lsb() -> None:
    rows = [_row(1.0), _row(2.0), _row(3.0, "uncompensated"), _row(4.0), _row(5.0, "harm")]
    assert derived_limit(rows) == 2.0 and harmless_limit(rows) == 4.0
    assert derived_limit([_row(1.0, "costly")]) is None


def test_every_accepted_limit_is_on_its_grid() -> None:
    acc = accepted_limits()
    assert acc == {s.key: s.resolution for s in LOGICAL_SIGNALS if s.resolution is not None}
    for key, lim in acc.items():
        assert lim in grid(key) and native_lsb(key) <= lim, key


def test_every_signal_at_its_accepted_limit_does_no_harm(tmp_path: Path) -> None:
    rows = sweep([], (1,), 1, tmp_path)
    assert [r.key for r in rows] == [NATIVE, ALL_AT_LIMITS]
    assert rows[0].fine, rows[0].faults
    at_limits = rows[1]
    assert at_limits.fine, [(c.scenario, f) for c, f in zip(at_limits.cells, at_limits.faults, strict=True)]
    assert len(at_limits.cells) == 4  # cases 1–3 and fault-free, one seed
