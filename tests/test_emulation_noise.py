"""The emulation's sensor noise: seeded per stream, drawn in blocks, the same draws whatever the
block boundaries (a run's samples are reproducible for any length)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.emulation import _BLOCK, PlantEmulation
from ehpss_hil.physics.load import load_params
from ehpss_hil.scenario import Noise, load_scenario


def test_noise_is_sigma_times_each_seeded_stream_across_blocks() -> None:
    sc = load_scenario(PROJECT_ROOT / "scenarios" / "fault-free.yaml")
    sc = replace(sc, duration_s=10.0, events=(), noise=Noise(2e-6, 3e-8, 5e4), seed=7)
    emu = PlantEmulation(load_params(), sc)
    n = _BLOCK + 100  # across a block boundary
    got = np.empty((n, 3))
    for k in range(n):
        s = emu.measure()
        got[k] = (s.position_m - s.true_position_m, s.spool_m - s.true_spool_m, s.load_pressure_pa)
        emu.advance(0.0)  # at rest: the plant stays at the origin, the readings are the noise
    for i, sigma in enumerate((2e-6, 3e-8, 5e4)):
        want = sigma * np.random.default_rng([7, i]).standard_normal(n)
        np.testing.assert_array_equal(got[:, i], want)
    emu.reset()  # identically seeded again
    assert emu.measure().position_m == got[0, 0]


def test_frame_losses_are_both_directions_draws_across_blocks_and_a_loss_change() -> None:
    """``frame_losses()`` (the simulator's one call per sample) draws exactly what
    ``frame_lost(0)`` and ``frame_lost(1)`` draw on an identically seeded emulation, sample for
    sample across a block boundary, with the two directions' probabilities kept apart."""
    from ehpss_hil.scenario import FrameLoss

    sc = load_scenario(PROJECT_ROOT / "scenarios" / "fault-free.yaml")
    sc = replace(sc, duration_s=10.0, events=(), seed=11)
    one, two = PlantEmulation(load_params(), sc), PlantEmulation(load_params(), sc)
    got, want = [], []
    for k in range(_BLOCK + 50):
        if k == 100:  # a change of the loss (as a scheduled event or an injection makes it)
            one.loss = two.loss = FrameLoss(0.3, 0.7)
        got.append(one.frame_losses())
        want.append((two.frame_lost(0), two.frame_lost(1)))
    assert got == want
    sensor, command = np.array(got[100:]).mean(axis=0)
    assert abs(sensor - 0.3) < 0.03 and abs(command - 0.7) < 0.03
    assert not any(any(g) for g in got[:100])  # no loss before the change
