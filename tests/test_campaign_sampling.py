"""Campaign sampling: runs come from the file's content and the run index only; samplers fill
the unit cube; ramps are staircases that end at the sampled magnitude."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _proc import ROOT

from ehpss_hil.campaign.journal import Journal, read_journal
from ehpss_hil.campaign.sampling import RAMP_STEPS, Fault, fault_events, plan_runs, unit_points
from ehpss_hil.campaign.spec import load_campaign

FILE = """\
name: s
base: {base}
samples: 64
sampler: {sampler}
duration_s: 2.0
faults:
  count: [1, 3]
  onset_s: [0.2, 1.5]
  ramp_s: [0.1, 0.4]
  ramp_share: 0.5
  kinds: {{loe: {{weight: 3}}, kq: {{}}, sensor_failure: {{}}, frame_loss: {{magnitude: [0.05, 0.1]}}}}
"""


def _write(tmp_path: Path, sampler: str = "sobol", text: str | None = None, name: str = "") -> Path:
    p = tmp_path / f"{name or sampler}.yaml"
    p.write_text(text or FILE.format(base=ROOT / "scenarios" / "case1-loe.yaml", sampler=sampler))
    return p


def test_layout_and_comments_do_not_change_the_runs_but_the_seed_does(tmp_path: Path) -> None:
    a = load_campaign(_write(tmp_path))
    text = "# a comment\n" + FILE.format(base=ROOT / "scenarios" / "case1-loe.yaml", sampler="sobol")
    moved = "\n".join(reversed(text.split("\n", 4)[:4])) + "\n" + text.split("\n", 4)[4]
    b = load_campaign(_write(tmp_path, "sobol", moved, name="moved"))
    assert a.content_hash == b.content_hash
    assert [p.run_hash for p in plan_runs(a)] == [p.run_hash for p in plan_runs(b)]
    c = load_campaign(
        _write(tmp_path, text=text.replace("samples: 64", "samples: 64\nseed: 9"), name="seed9")
    )
    assert c.content_hash != a.content_hash
    assert plan_runs(c)[0].scenario.seed != plan_runs(a)[0].scenario.seed


def test_where_the_base_scenario_lives_does_not_change_the_runs_but_its_content_does(
    tmp_path: Path,
) -> None:
    """The same campaign and base scenario in another checkout (another absolute path, or the
    base beside the file) draw the same runs; an edited base scenario draws others."""
    a = load_campaign(_write(tmp_path))
    other = tmp_path / "elsewhere"
    other.mkdir()
    base = (ROOT / "scenarios" / "case1-loe.yaml").read_text()
    (other / "case1-loe.yaml").write_text(base)
    b = load_campaign(_write(other, text=FILE.format(base="case1-loe.yaml", sampler="sobol")))
    assert a.content_hash == b.content_hash
    assert [p.run_hash for p in plan_runs(a)] == [p.run_hash for p in plan_runs(b)]
    (other / "case1-loe.yaml").write_text(base.replace("seed: ", "seed: 1", 1))
    c = load_campaign(_write(other, text=FILE.format(base="case1-loe.yaml", sampler="sobol"), name="c"))
    assert c.content_hash != a.content_hash


@pytest.mark.parametrize("sampler", ["random", "lhs", "sobol"])
def test_samplers_fill_the_unit_cube(sampler: str) -> None:
    pts = unit_points(sampler, 256, 5, seed=7)
    assert pts.shape == (256, 5) and pts.min() >= 0.0 and pts.max() < 1.0
    # every tenth of every axis is visited (a stratified sampler puts 25-26 points in each)
    counts = np.stack([np.histogram(pts[:, j], bins=10, range=(0, 1))[0] for j in range(5)])
    assert counts.min() >= (25 if sampler != "random" else 10)
    assert np.array_equal(pts, unit_points(sampler, 256, 5, seed=7))


@pytest.mark.parametrize("sampler", ["random", "lhs", "sobol"])
def test_runs_respect_the_distributions(tmp_path: Path, sampler: str) -> None:
    plans = plan_runs(load_campaign(_write(tmp_path, sampler)))
    assert len(plans) == 64 and len({p.run_hash for p in plans}) == 64
    counts = {1: 0, 2: 0, 3: 0}
    for p in plans:
        counts[len(p.faults)] += 1
        assert len({f.kind for f in p.faults}) == len(p.faults)  # distinct kinds
        for f in p.faults:
            assert 0.2 <= f.onset_s <= 1.5
            assert f.ramp_s == 0.0 or (0.1 <= f.ramp_s <= 0.4 and f.kind in ("loe", "kq", "frame_loss"))
            if f.kind == "frame_loss":
                assert 0.05 <= f.magnitude <= 0.1
            if f.kind == "sensor_failure":
                assert f.magnitude == 0.0
        assert p.scenario.duration_s == 2.0 and p.scenario.events
    assert min(counts.values()) >= 10
    loe = sum(any(f.kind == "loe" for f in p.faults) for p in plans)
    kq = sum(any(f.kind == "kq" for f in p.faults) for p in plans)
    assert loe > kq  # weight 3 against 1


def test_a_ramp_is_a_staircase_to_the_magnitude_and_events_stay_in_order() -> None:
    evs = fault_events((Fault("loe", 0.5, 1.0, 0.5), Fault("stuck", 1.0, 1.2, 0.0)), duration_s=2.0)
    loe = [e for e in evs if e.k_loe is not None]
    assert len(loe) == RAMP_STEPS
    assert [e.t_s for e in loe] == [round(1.0 + 0.05 * s, 4) for s in range(1, RAMP_STEPS + 1)]
    assert loe[0].k_loe == pytest.approx(0.95) and loe[-1].k_loe == 0.5
    assert [e.t_s for e in evs] == sorted(e.t_s for e in evs)
    assert [e.stuck for e in evs if e.stuck is not None] == [True]
    cut = fault_events((Fault("loe", 0.5, 1.8, 0.5),), duration_s=2.0)
    assert cut[-1].t_s <= 2.0 and len(cut) == 4  # steps beyond the run's end are dropped


def test_the_journal_drops_a_torn_tail_and_is_locked(tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl"
    with Journal(path) as j:
        j.append({"run_hash": "a", "metrics": {"x": float("inf")}})
        with pytest.raises(OSError, match="in use"):
            Journal(path)
    with open(path, "ab") as f:
        f.write(b'{"run_hash": "b", "met')
    with Journal(path) as j:
        j.append({"run_hash": "c", "metrics": {"x": 1.5}})
    recs = read_journal(path)
    assert sorted(recs) == ["a", "c"] and recs["a"]["metrics"]["x"] == float("inf")
