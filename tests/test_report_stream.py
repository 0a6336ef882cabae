"""``report`` on logs beyond its in-memory cap (issue #29): read in chunks, the same metrics as
the whole log, figures from a min/max view, memory that does not grow with the log.

Equality is checked on the shipped scenarios' lockstep logs with chunks far smaller than the
logs (997 commands: cuts fall between status frames, inside event windows and fallback
intervals); the memory bound on generated logs of 0.2 M and 0.6 M samples in child processes,
each writing its own VmHWM at exit.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from longlogs import long_log, tile_log
from test_log_streaming import _stepped
from test_report_log import short_case1

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.report.decimate import MinMaxDecimator
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.report.logmetrics import LogMetrics, log_metrics
from ehpss_hil.report.logviews import log_view
from ehpss_hil.report.streamed import STREAM_ABOVE_BYTES, stream_log_run
from ehpss_hil.scenario import load_scenario
from ehpss_hil.sim.samplelog import write_lockstep_log

SHIPPED = sorted((PROJECT_ROOT / "scenarios").glob("*.yaml"))
#: the two logs' lengths (samples) whose peaks are compared: both beyond the size a log is
#: streamed from, as short as that allows (the report reads ~6 000 samples a second here)
SHORT_SAMPLES, LONG_SAMPLES = 200_000, 600_000
#: the peak RSS of the longer log's report may exceed the shorter one's by this (MB): 30 bytes a
#: sample over the samples between them (measured: 0.6 and 0.8 MB more for 0.7 M samples than
#: for 0.2 M, peaks ≈ 157 MB)
RSS_GROWTH_MB = 30e-6 * (LONG_SAMPLES - SHORT_SAMPLES)


def _same_metrics(whole: LogMetrics, part: LogMetrics) -> None:
    a, b = whole.run, part.run
    assert a is not None and b is not None
    assert b.rms_error_m == pytest.approx(a.rms_error_m, rel=1e-12)  # summed in another order
    assert (b.pre_fault_max_m, b.max_error_m, b.switches) == (a.pre_fault_max_m, a.max_error_m, a.switches)
    assert [vars(e) for e in b.events] == [vars(e) for e in a.events]
    assert (b.scenario, b.controller, b.duration_s) == (a.scenario, a.controller, a.duration_s)
    ea, eb = dict(whole.extra), dict(part.extra)
    assert eb.pop("sensor_rms_error_m") == pytest.approx(ea.pop("sensor_rms_error_m"), rel=1e-12)
    assert eb == ea and part.unavailable == whole.unavailable


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_streamed_metrics_equal_the_whole_logs(path: Path, tmp_path: Path) -> None:
    log = write_lockstep_log(load_scenario(path), "mmac", tmp_path / "run.log")
    whole = load_log_run(log)
    view = log_view(whole)
    s = stream_log_run(log, chunk_samples=997)
    assert len(whole.result.t_s) > 2 * 997  # several chunks
    _same_metrics(log_metrics(whole), s.metrics)
    assert s.view.events == view.events and s.view.intervals == view.intervals
    assert s.run.notes == whole.notes
    assert s.frame_counts == {n: len(f["t_s"]) for n, f in whole.frames.items()}


def test_the_fallback_intervals_cross_chunk_boundaries(tmp_path: Path) -> None:
    """case 4's fallback intervals (80–120 samples long), cut by chunks of 37 commands, come
    out whole."""
    log = write_lockstep_log(
        load_scenario(PROJECT_ROOT / "scenarios" / "case4-disturbance.yaml"), "mmac", tmp_path / "r.log"
    )
    want = log_view(load_log_run(log)).intervals
    assert len(want) >= 2 and all(iv.t1_s - iv.t0_s > 0.05 for iv in want)
    assert stream_log_run(log, chunk_samples=37).view.intervals == want


@pytest.mark.parametrize(
    ("step_s", "realtime", "words"), [(-0.05, False, "-0.050 s"), (3600.0, True, "+3600.000 s")]
)
def test_a_clock_step_is_undone_in_whichever_chunk_it_falls(
    step_s: float, realtime: bool, words: str, tmp_path: Path
) -> None:
    """A step at half the file (sample ≈ 600): in a chunk's middle (chunks of 250) and right
    after a cut (chunks of 600): noted once, the metrics as read whole."""
    base = write_lockstep_log(short_case1(), "mmac", tmp_path / "base" / "run.log")
    log = _stepped(base, tmp_path / "step" / "run.log", step_s)
    if realtime:  # the wall clock follows the cycles: the step is found on the CycleCount
        side = log.with_name("run.log.json")
        side.write_text(json.dumps({**json.loads(side.read_text()), "lockstep": False}))
    whole = load_log_run(log)
    assert sum(words in n for n in whole.notes) == 1, whole.notes
    for chunk in (250, 600):
        s = stream_log_run(log, chunk_samples=chunk)
        assert sum(words in n for n in s.run.notes) == 1, s.run.notes
        _same_metrics(log_metrics(whole), s.metrics)


def test_min_max_view_keeps_every_spike_within_its_budget() -> None:
    """1 M samples fed in parts of 30 011: at most 2 000 rows drawn, the largest and smallest
    error and a one-sample current spike at their values, every row's time a sample's."""
    n, part = 1_000_000, 30_011
    rng = np.random.default_rng(7)
    t = np.arange(n) * 1e-3
    err = rng.normal(0, 1e-6, n)
    err[123_457], err[876_543] = 5e-4, -3e-4
    cur = np.zeros(n)
    cur[654_321] = 0.9
    dec = MinMaxDecimator(max_samples=2000)
    for a in range(0, n, part):
        s = slice(a, a + part)
        m = len(t[s])
        dec.add(
            {
                "t_s": t[s], "x_d_m": np.zeros(m), "y_m_m": np.zeros(m), "x_true_m": err[s],
                "y_s_m": err[s], "spool_m": np.zeros(m), "current_a": cur[s],
                "active_spool": np.zeros(m, np.int64), "active_position": np.zeros(m, np.int64),
                "k_loe_hat": np.ones(m), "k_dft_hat": np.ones(m), "index": np.full((m, 16), np.nan),
                "true_k_loe": np.ones(m), "true_k_q": np.ones(m), "true_k_dft": np.ones(m),
                "fresh": np.ones(m, bool), "stuck": np.zeros(0, bool), "commanded_a": cur[s],
            }
        )  # fmt: skip
    rows = dec.rows()
    assert len(rows["t_s"]) <= 2000 + 2 * dec.size
    assert rows["x_true_m"].max() == 5e-4 and rows["x_true_m"].min() == -3e-4
    assert rows["current_a"].max() == 0.9 and rows["commanded_a"].max() == 0.9
    assert np.isin(rows["t_s"], t).all() and np.all(np.diff(rows["t_s"]) >= 0)
    assert rows["index"].shape == (len(rows["t_s"]), 16)


def _report_child(log: Path, out: Path) -> tuple[int, float, str]:
    """``ehpss-hil report LOG --out OUT --no-figures`` in a child: exit code, its own peak RSS
    (MB, VmHWM written at exit: ru_maxrss would carry pytest's high-water mark) and its output."""
    hwm = out.with_suffix(".hwm")
    code = (
        "import atexit, re, sys\n"
        f"atexit.register(lambda: open({str(hwm)!r}, 'w').write("
        "re.search(r'VmHWM:\\s*(\\d+)', open('/proc/self/status').read()).group(1)))\n"
        "from ehpss_hil.cli import main\nsys.exit(main(sys.argv[1:]))"
    )
    p = subprocess.run(
        [sys.executable, "-c", code, "report", str(log), "--out", str(out), "--no-figures"],
        capture_output=True,
        text=True,
    )
    return p.returncode, int(hwm.read_text()) / 1024, p.stdout + p.stderr


@pytest.mark.slow
def test_report_memory_does_not_grow_with_the_log(tmp_path: Path) -> None:
    """0.2 M and 0.6 M samples (38 MB and 114 MB of candump, both beyond the size a log is
    streamed from): both reported, the 0.6 M one's peak RSS within :data:`RSS_GROWTH_MB` of the
    0.2 M one's — 30 bytes a sample more over the samples between them would fail it;
    whatever a whole log holds per sample (≈ 0.9 kB) or the metrics' per-sample columns (≈ 50
    bytes, spilled to a scratch file) kept in memory would. Without figures: their memory
    depends on what they draw (a dense zigzag costs Agg tens of MB), not on the log's length
    (measured by hand up to 4 M samples: docs/logs.md)."""
    tile = tile_log(tmp_path)
    peaks = {}
    for n in (SHORT_SAMPLES, LONG_SAMPLES):
        log = long_log(tile, tmp_path / f"l{n}" / "run.log", n)
        assert log.stat().st_size > STREAM_ABOVE_BYTES  # both streamed: the chunks' memory is compared
        rc, peak, text = _report_child(log, tmp_path / f"r{n}")
        log.unlink()
        assert rc == 0, text
        assert f"metrics use every sample ({n})" in text, text
        assert json.loads((tmp_path / f"r{n}" / "metrics.json").read_text())[0]["extra"]["samples"] == n
        peaks[n] = peak
    assert peaks[LONG_SAMPLES] < peaks[SHORT_SAMPLES] + RSS_GROWTH_MB, peaks
