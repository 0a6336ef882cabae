"""Campaign coverage maps follow the data: cells from the number of runs (about four runs a cell),
and a fault kind without a magnitude (stuck, sensor failure) mapped over its onset alone."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ehpss_hil.campaign.figures import (
    MAGNITUDE_LABEL,
    MAX_BINS,
    binned_median,
    coverage_onset,
    map_bins,
    onset_figure,
)
from ehpss_hil.campaign.spec import FAULT_KINDS, MAGNITUDE_BOUNDS


@pytest.mark.parametrize(
    ("runs", "axes", "bins"), [(1, 2, 1), (14, 2, 2), (14, 1, 4), (64, 2, 4), (580, 2, 12)]
)
def test_bins_per_axis_come_from_the_number_of_runs(runs: int, axes: int, bins: int) -> None:
    assert map_bins(runs, axes) == bins
    assert map_bins(10**6) == MAX_BINS


def test_fourteen_runs_make_a_two_by_two_map_with_the_median_per_cell() -> None:
    x = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.45, 0.49, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99, 1.0])
    y = np.array([0.0] * 7 + [1.0] * 7)  # lower row left half, upper row right half
    v = np.arange(14.0)
    xe, _ye, grid = binned_median(x, y, v)
    assert grid.shape == (2, 2)
    np.testing.assert_allclose(xe, [0.0, 0.5, 1.0])
    assert grid[0, 0] == 3.0 and grid[1, 1] == 10.0  # medians of 0…6 and 7…13
    assert math.isnan(grid[0, 1]) and math.isnan(grid[1, 0])


def test_a_kind_without_magnitude_is_one_row_over_its_onset() -> None:
    x = np.linspace(0.0, 2.0, 14)
    _xe, ye, grid = binned_median(x, None, np.ones(14))
    assert grid.shape == (1, 4) and list(ye) == [0.0, 1.0]
    assert not np.isnan(grid).any()


def test_every_kind_with_a_magnitude_has_an_axis_label_and_no_other() -> None:
    assert set(MAGNITUDE_LABEL) == set(MAGNITUDE_BOUNDS)
    assert {"stuck", "sensor_failure"} <= set(FAULT_KINDS) - set(MAGNITUDE_LABEL)


def test_the_onset_map_of_stuck_has_no_magnitude_axis(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = []
    for i in range(28):
        row = {f"{k}.{c}": math.nan for k in FAULT_KINDS for c in ("onset_s", "magnitude")}
        kind = "stuck" if i % 2 else "loe"
        row |= {f"{kind}.onset_s": 0.1 * i, f"{kind}.magnitude": 1.0 if kind == "stuck" else 0.3 + 0.02 * i}
        row |= {"mmac.rms_error_m": 1e-5 * (i + 1), "oracle.rms_error_m": 1e-5}
        rows.append(row)
    fig = onset_figure(rows)
    try:
        loe, stuck = (ax for ax in fig.axes if ax.get_visible() and ax.get_title())
        assert loe.get_title() == "loe (14 runs)" and loe.get_ylabel() == "k_LOE"
        assert stuck.get_title() == "stuck (14 runs)" and stuck.get_ylabel() == ""
        assert list(stuck.get_yticks()) == []
        assert loe.get_facecolor() == stuck.get_facecolor() != (1.0, 1.0, 1.0, 1.0)  # empty: not white
        assert loe.collections[0].get_array().shape == (2, 2)  # 14 runs: 2 × 2 cells
        assert stuck.collections[0].get_array().shape == (1, 4)  # over the onset only: 4 cells
    finally:
        plt.close(fig)
    assert coverage_onset(rows, tmp_path / "onset.png") == tmp_path / "onset.png"
    assert (tmp_path / "onset.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
