"""Fault campaigns: the same file gives the bit-identical table on 1 and 2 local workers, after a
SIGKILL and --resume, and the worst cases rerun exactly with ``ehpss-hil sim``. Tiny campaigns of
0.5-s runs (Dask: tests/test_campaign_dask.py)."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from _campaign import LIMIT_S, cli, digest, tiny, wait_lines
from _proc import EHPSS_HIL, ENV, ROOT

from ehpss_hil.campaign.journal import JOURNAL_NAME, read_journal
from ehpss_hil.campaign.session import run_campaign
from ehpss_hil.campaign.spec import load_campaign
from ehpss_hil.campaign.table import PARQUET_NAME

#: the killed-and-resumed campaign: enough runs that a loaded host cannot finish them all
#: between the third journal line and the SIGKILL, few enough to run twice more
RESUMED_SAMPLES = 120


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The tiny campaign file and its table from one worker in this process."""
    d = tmp_path_factory.mktemp("campaign")
    f = tiny(d / "tiny.yaml")
    run_campaign(load_campaign(f), d / "one", workers=1, figures=False)
    return f, d / "one"


def test_the_table_holds_one_row_per_run_with_real_metrics(reference: tuple[Path, Path]) -> None:
    _f, one = reference
    rows = pq.read_table(one / PARQUET_NAME).to_pylist()
    assert [r["index"] for r in rows] == list(range(8))
    for r in rows:
        for mode in ("nrc", "mmac", "oracle"):
            assert r[f"{mode}.rms_error_m"] > 0.0
            assert r[f"{mode}.max_error_m"] >= r[f"{mode}.rms_error_m"]
        assert r["nrc.switches"] == 0 and r["nrc.active_spool"] == -1  # nrc has no bank
        kinds = sorted(
            k for k in ("loe", "drift", "stuck", "bias", "frame_loss") if not math.isnan(r[f"{k}.onset_s"])
        )
        assert r["fault_class"] == "+".join(kinds) and r["n_faults"] == len(kinds)
        if not math.isnan(r["loe.magnitude"]):
            assert 0.3 <= r["loe.magnitude"] <= 0.8
    # the runs with an LOE: mmac never worse than the plain loop by more than the no-harm margin,
    # and far better in some (where the spool is not saturated anyway, as on a square wave,
    # which leaves the three modes equal)
    loe = [r for r in rows if "loe" in r["fault_class"].split("+")]
    assert loe
    for r in loe:
        assert r["mmac.rms_error_m"] <= 1.1 * r["nrc.rms_error_m"] + 1e-6
    assert any(r["mmac.rms_error_m"] < 0.5 * r["nrc.rms_error_m"] for r in rows)


def test_two_local_workers_give_the_bit_identical_table(reference: tuple[Path, Path], tmp_path: Path) -> None:
    f, one = reference
    res = run_campaign(load_campaign(f), tmp_path / "two", workers=2, figures=False)
    assert res.ran == 8
    assert digest(tmp_path / "two") == digest(one)


def test_resume_after_sigkill_skips_finished_runs_and_ends_with_the_same_table(tmp_path: Path) -> None:
    f = tiny(tmp_path / "tiny.yaml", samples=RESUMED_SAMPLES)
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        [*EHPSS_HIL, "campaign", str(f), "--workers", "2", "--out", str(out), "--no-figures"],
        cwd=ROOT,
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        wait_lines(out / JOURNAL_NAME, 3, proc)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the campaign and its pool, at once
        proc.wait()
    kept = read_journal(out / JOURNAL_NAME)
    assert 3 <= len(kept) < RESUMED_SAMPLES
    with open(out / JOURNAL_NAME, "ab") as j:  # a torn record, as a power cut would leave it
        j.write(b'{"run_hash": "abc", "metr')
    again = cli("campaign", str(f), "--workers", "2", "--out", str(out), "--resume", "--no-figures")
    assert again.returncode == 0, again.stderr
    assert f"{RESUMED_SAMPLES - len(kept)} run(s) done" in again.stdout
    assert f"{len(kept)} skipped" in again.stdout
    fresh = run_campaign(load_campaign(f), tmp_path / "fresh", workers=1, figures=False)
    assert fresh.ran == RESUMED_SAMPLES
    assert digest(out) == digest(tmp_path / "fresh")
    assert len(read_journal(out / JOURNAL_NAME)) == RESUMED_SAMPLES


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_stops_keeps_finished_runs_and_exits_130(tmp_path: Path) -> None:
    # far more runs than are done before the signal lands, however long a loaded host keeps
    # this test from sending it: the rest is never run
    f = tiny(tmp_path / "tiny.yaml", samples=2000)
    out = tmp_path / "int"
    proc = subprocess.Popen(
        [*EHPSS_HIL, "campaign", str(f), "--workers", "2", "--out", str(out), "--no-figures"],
        cwd=ROOT,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        # a foreground command's Ctrl-C: the test may itself run where SIGINT is ignored (a
        # background job of a non-interactive shell), which a child would inherit, and Python
        # keeps an inherited SIG_IGN (the campaign then runs all 2000 runs and exits 0)
        preexec_fn=_default_sigint,
    )
    wait_lines(out / JOURNAL_NAME, 2, proc)
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: to the whole group
    _stdout, stderr = proc.communicate(timeout=LIMIT_S)
    assert proc.returncode == 130, stderr
    assert b"Traceback" not in stderr and b"--resume" in stderr
    assert len(read_journal(out / JOURNAL_NAME)) >= 2


def test_worst_case_scenarios_rerun_exactly_with_sim(reference: tuple[Path, Path], tmp_path: Path) -> None:
    f, _one = reference
    out = tmp_path / "worst"
    assert cli("campaign", str(f), "--workers", "1", "--out", str(out), "--no-figures").returncode == 0
    rows = {r["index"]: r for r in pq.read_table(out / PARQUET_NAME).to_pylist()}
    summary = json.loads((out / "summary.json").read_text())["classes"]
    assert summary[-1]["fault_class"] == "all" and summary[-1]["runs"] == 8
    assert sum(c["runs"] for c in summary[:-1]) == 8
    md = (out / "summary.md").read_text()
    for order, other in (("harm", "nrc"), ("gap", "oracle")):
        # the worst five of all runs by mmac − nrc and by mmac − oracle, largest first
        ranked = sorted(
            rows.values(), key=lambda r: (r[f"{other}.rms_error_m"] - r["mmac.rms_error_m"], r["index"])
        )
        listed = summary[-1][f"worst_{order}"]
        assert [w["index"] for w in listed] == [r["index"] for r in ranked[:5]]
        top = ranked[0]
        assert listed[0][f"{order}_m"] == top["mmac.rms_error_m"] - top[f"{other}.rms_error_m"]
        assert f"run {top['index']}: {listed[0][f'{order}_m'] * 1e6:+.1f}" in md
        files = sorted((out / "worst" / "all").glob(f"{order}-*.yaml"))
        assert [p.name for p in files] == [
            f"{order}-{k}-run{w['index']:05d}.yaml" for k, w in enumerate(listed, 1)
        ]
    assert "## Most harm (mmac − nrc RMS)" in md and "## Largest gap to the oracle (mmac − oracle RMS)" in md
    section = ""
    for line in md.splitlines():  # each class's list links the files in its own folder
        section = line[4:] if line.startswith("### ") else section
        if "| worst/" in line:
            assert line.split("| ")[-1].startswith(f"worst/{section}/"), line
    for path in sorted((out / "worst" / "all").glob("harm-*.yaml"))[:2]:
        index = int(path.stem.split("run")[1])
        js = tmp_path / f"{path.stem}.json"
        sim = cli("sim", str(path), "-C", "nrc", "-C", "mmac", "-C", "oracle", "--json", str(js), "-j", "1")
        assert sim.returncode == 0, sim.stderr
        for m in json.loads(js.read_text()):
            assert m["rms_error_m"] == rows[index][f"{m['controller']}.rms_error_m"]  # bit for bit
            assert m["switches"] == rows[index][f"{m['controller']}.switches"]


def test_an_existing_campaign_directory_needs_resume(reference: tuple[Path, Path]) -> None:
    f, one = reference
    out = cli("campaign", str(f), "--out", str(one))
    assert out.returncode == 2
    assert "--resume" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ("samples: 8", "samples"),
        ("samples: 0", "samples"),
        ("sampler: lhs", "sampler"),
        ("loe: {magnitude: [0.3, 0.8]}", "faults.kinds.loe.magnitude"),
        ("count: [1, 2]", "faults.count"),
        ("duration_s: 0.5", "faults.onset_s"),
        ("seed: 3", "colour"),
        ("stuck: {}", "faults.kinds.stuck.magnitude"),
    ],
)
def test_bad_campaign_files_are_one_line_errors_naming_file_and_key(
    tmp_path: Path, change: str, key: str
) -> None:
    bad = {
        "samples: 8": "samples: eight",
        "samples: 0": "samples: 0",
        "sampler: lhs": "sampler: halton",
        "loe: {magnitude: [0.3, 0.8]}": "loe: {magnitude: [0.8, 0.3]}",
        "count: [1, 2]": "count: [1, 6]",
        "duration_s: 0.5": "duration_s: 0.2",
        "seed: 3": "seed: 3\ncolour: red",
        "stuck: {}": "stuck: {magnitude: [1, 1]}",
    }[change]
    f = tiny(tmp_path / "bad.yaml")
    f.write_text(
        f.read_text().replace(change, bad)
        if change != "samples: 0"
        else f.read_text().replace("samples: 8", bad)
    )
    out = cli("campaign", str(f), "--out", str(tmp_path / "o"))
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and str(f) in lines[0] and f": {key}:" in lines[0], lines


def test_an_oversized_campaign_file_is_refused(tmp_path: Path) -> None:
    f = tiny(tmp_path / "big.yaml")
    f.write_text(f.read_text() + "#" * (300 * 1024) + "\n")
    out = cli("campaign", str(f))
    assert out.returncode == 2 and "larger than" in out.stderr


def test_the_shipped_campaigns_load() -> None:
    quick = load_campaign(ROOT / "campaigns" / "quick.yaml")
    qual = load_campaign(ROOT / "campaigns" / "qualification.yaml")
    assert 40 <= quick.spec.samples <= 64 and qual.spec.samples >= 2000
    model_error = load_campaign(ROOT / "campaigns" / "model-error.yaml")
    for camp in (quick, qual, model_error):  # the description says the number of runs sampled
        assert camp.spec.description.startswith(f"{camp.spec.samples} runs"), camp.spec.description
    out = cli(
        "check-config", str(ROOT / "campaigns" / "quick.yaml"), str(ROOT / "campaigns" / "qualification.yaml")
    )
    assert out.returncode == 0, out.stderr
    assert "campaign quick: 48 runs of 3 s (sobol)" in out.stdout
    assert "campaign qualification: 2048 runs" in out.stdout


def test_bench_campaign_prints_every_row_and_writes_its_figures(tmp_path: Path) -> None:
    js = tmp_path / "bench.json"
    out = cli("bench", "campaign", "--runs", "2", "--no-dask", "--json", str(js))
    # its targets (speed-up, mmac speed) depend on the host's load: the exit code follows them
    failed = [line for line in out.stdout.splitlines()[:-1] if line.rstrip().endswith("FAIL")]
    assert out.returncode == (1 if failed else 0), out.stdout + out.stderr
    last = out.stdout.splitlines()[-1]
    assert last.startswith(f"bench campaign: {len(failed)} of") if failed else last.endswith("target(s) PASS")
    assert "speed-up local ×2 / ×1" in out.stdout and "mmac offline speed" in out.stdout
    data = json.loads(js.read_text())
    assert [e["runs"] for e in data["executors"]] == [2, 2]
    assert all(e["run_s"] > 0.0 for e in data["executors"]) and data["mmac_speed"]["median"] > 0.0


def test_a_bad_scheduler_address_is_one_line_exit_3(reference: tuple[Path, Path], tmp_path: Path) -> None:
    f, _one = reference
    out = cli("campaign", str(f), "--scheduler", "bogus://x", "--out", str(tmp_path / "o"))
    assert out.returncode == 3
    errors = [line for line in out.stderr.splitlines() if "error" in line.lower()]
    assert len(errors) == 1 and "bad Dask scheduler address 'bogus://x'" in errors[0]
    assert "Traceback" not in out.stderr


def test_kill_9_of_the_campaign_ends_its_pool_without_a_traceback(tmp_path: Path) -> None:
    f = tiny(tmp_path / "tiny.yaml", samples=RESUMED_SAMPLES)
    out = tmp_path / "k9"
    proc = subprocess.Popen(
        [*EHPSS_HIL, "campaign", str(f), "--workers", "2", "--out", str(out), "--no-figures"],
        cwd=ROOT,
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        wait_lines(out / JOURNAL_NAME, 2, proc)
        os.kill(proc.pid, signal.SIGKILL)  # the campaign alone: its pool workers are left to themselves
        # EOF on stderr once every holder of the pipe, the pool workers too, has ended
        _stdout, stderr = proc.communicate(timeout=LIMIT_S)
    finally:
        os.killpg(proc.pid, signal.SIGKILL) if proc.poll() is None else None
    assert proc.returncode == -signal.SIGKILL
    assert b"Traceback" not in stderr and b"BrokenPipeError" not in stderr, stderr.decode()[-2000:]
    assert len(read_journal(out / JOURNAL_NAME)) < RESUMED_SAMPLES
