"""Logs are streamed, not loaded (issue #29, items 5 and 6): ``report`` and ``replay`` on hostile
logs — reversed, mirrored, long, growing, a FIFO or a device, deep or huge sidecars, absurd
sample times, small clock steps — end with one line and an exit code, in bounded memory.

The commands run as real child processes (``ehpss-hil`` through :func:`ehpss_hil.cli.main`); their
peak RSS is the kernel's ``ru_maxrss`` of that child alone (``os.wait4``). The "2 GB log" rows are
tested on logs of a few tens of MB with the caps scaled down in the child (the mechanism:
memory that stops growing with the file); the 2 GB figures were measured by hand (CHANGELOG).
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from test_report_log import short_case1

from ehpss_hil.canlog.order import OutOfOrderError, TimeOrder
from ehpss_hil.report.decimate import thinned
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.report.logmetrics import log_metrics
from ehpss_hil.sim.samplelog import write_lockstep_log

#: a child that only refuses its input stays near the interpreter + numpy (≈ 50 MB)
SMALL_RSS_MB = 150.0
#: safety net for a child that would hang (a FIFO read); never reached when the code is right
HANG_S = 300.0


@dataclass
class Child:
    rc: int
    out: str
    err: str
    peak_rss_mb: float

    @property
    def err_lines(self) -> list[str]:
        return [ln for ln in self.err.splitlines() if ln.strip()]


def cli(args: list[str], tmp: Path, prelude: str = "", rlimits: dict[int, int] | None = None) -> Child:
    """``ehpss-hil ARGS`` in a child process (``prelude`` runs first, e.g. caps scaled down;
    ``rlimits`` set in the child): exit code, output and the child's own peak RSS — its VmHWM
    written at exit (``wait4``'s ru_maxrss carries the forking parent's high-water mark across
    exec: a child of a large pytest process would report the parent's); ru_maxrss only when the
    child died before it could write it."""
    hwm = tmp / "child.hwm"
    hwm.unlink(missing_ok=True)
    code = (
        "import atexit, re, sys\n"
        f"atexit.register(lambda: open({str(hwm)!r}, 'w').write("
        "re.search(r'VmHWM:\\s*(\\d+)', open('/proc/self/status').read()).group(1)))\n"
        f"{prelude}\nfrom ehpss_hil.cli import main\nsys.exit(main(sys.argv[1:]))"
    )
    out, err = tmp / "child.out", tmp / "child.err"

    def limit() -> None:
        for res, value in (rlimits or {}).items():
            resource.setrlimit(res, (value, value))

    with open(out, "w") as fo, open(err, "w") as fe:
        p = subprocess.Popen([sys.executable, "-c", code, *args], stdout=fo, stderr=fe, preexec_fn=limit)
        alarm = subprocess.Popen(
            [sys.executable, "-c", f"import os,signal,time; time.sleep({HANG_S}); os.kill({p.pid}, 9)"]
        )
        try:
            _, status, usage = os.wait4(p.pid, 0)
        finally:
            alarm.kill()
            alarm.wait()
        p.returncode = os.waitstatus_to_exitcode(status)
    own_kb = int(hwm.read_text()) if hwm.exists() and hwm.read_text().strip() else usage.ru_maxrss
    return Child(p.returncode, out.read_text(), err.read_text(), own_kb / 1024)


@pytest.fixture(scope="module")
def base_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_lockstep_log(short_case1(), "mmac", tmp_path_factory.mktemp("stream") / "run.log")


def _copy(src: Path, dst: Path, lines: list[str], sidecar: bool = True) -> Path:
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text("".join(lines))
    if sidecar:
        shutil.copy(src.with_name(src.name + ".json"), dst.with_name(dst.name + ".json"))
    return dst


def _retimed(line: str, t: float) -> str:
    return f"({t:017.6f}){line[19:]}"


def _t(line: str) -> float:
    return float(line[1:18])


def _one_line_error(c: Child, rc: int, *words: str) -> None:
    assert c.rc == rc, c.err
    assert len(c.err_lines) == 1 and "Traceback" not in c.err, c.err
    for w in words:
        assert w in c.err_lines[0], c.err_lines[0]


# ---- rows of the issue -------------------------------------------------------------------------
def test_a_reversed_log_is_one_line_not_an_array_of_millions(base_log: Path, tmp_path: Path) -> None:
    """Before: 12.2 GB in 39 s (the unwrapped CycleCount ran backwards into 130 M samples)."""
    lines = base_log.read_text().splitlines(keepends=True)
    rev = _copy(base_log, tmp_path / "rev" / "run.log", lines[::-1])
    for cmd in (["report", str(rev), "--no-figures", "--out", str(tmp_path / "r")], ["replay", str(rev)]):
        c = cli(cmd, tmp_path)
        _one_line_error(c, 2, "not in time order", "reorder window")
        assert c.peak_rss_mb < SMALL_RSS_MB


def test_mirrored_timestamps_are_refused_not_a_negative_sample_time(base_log: Path, tmp_path: Path) -> None:
    """Before: a sample time of -0.854 ms accepted, exit 0."""
    lines = base_log.read_text().splitlines(keepends=True)
    t_end = _t(lines[-1])
    mirrored = [_retimed(ln, 2 * t_end - _t(ln)) for ln in lines]
    log = _copy(base_log, tmp_path / "mir" / "run.log", mirrored, sidecar=False)
    c = cli(["report", str(log), "--no-figures", "--out", str(tmp_path / "r")], tmp_path)
    _one_line_error(c, 2, "not in time order")


def test_an_absurd_sample_time_is_refused(base_log: Path, tmp_path: Path) -> None:
    """Timestamps 1000× stretched (1 s per cycle) without metadata, and a sidecar rate of 1 mHz:
    no loop runs at either; one line each."""
    lines = base_log.read_text().splitlines(keepends=True)
    t0 = _t(lines[0])
    slow = _copy(
        base_log,
        tmp_path / "slow" / "run.log",
        [_retimed(ln, t0 + 1000 * (_t(ln) - t0)) for ln in lines],
        False,
    )
    c = cli(["report", str(slow), "--no-figures", "--out", str(tmp_path / "r")], tmp_path)
    _one_line_error(c, 2, "sample time 999.9 ms from the log's timing is outside 0.1…100 ms")
    odd = _copy(base_log, tmp_path / "odd" / "run.log", lines, sidecar=False)
    odd.with_name("run.log.json").write_text('{"rate_hz": 0.001}')
    c = cli(["report", str(odd), "--no-figures", "--out", str(tmp_path / "r2")], tmp_path)
    _one_line_error(c, 2, "sample time 1e+06 ms from the metadata is outside")


@pytest.mark.parametrize("command", ["report", "replay"])
def test_a_fifo_or_a_device_is_refused_without_waiting(command: str, base_log: Path, tmp_path: Path) -> None:
    """Before: report/replay on a FIFO hung for ever."""
    fifo = tmp_path / "bus.log"
    os.mkfifo(fifo)
    c = cli([command, str(fifo)], tmp_path)
    _one_line_error(c, 2, "a FIFO, not a log file")
    c = cli([command, "/dev/null"], tmp_path)
    _one_line_error(c, 2, "a character device")
    beside = _copy(
        base_log, tmp_path / "side" / "run.log", base_log.read_text().splitlines(keepends=True), False
    )
    os.mkfifo(beside.with_name("run.log.json"))
    c = cli([command, str(beside)], tmp_path)
    _one_line_error(c, 2, "run.log.json: sidecar refused", "a FIFO")


def test_deep_and_huge_sidecars_are_refused(base_log: Path, tmp_path: Path) -> None:
    """Before: a RecursionError traceback; 648 MB for a 300 MB sidecar."""
    lines = base_log.read_text().splitlines(keepends=True)
    deep = _copy(base_log, tmp_path / "deep" / "run.log", lines, sidecar=False)
    deep.with_name("run.log.json").write_text("[" * 2000 + "]" * 2000)
    for cmd in (["report", str(deep), "--no-figures"], ["replay", str(deep)]):
        _one_line_error(cli(cmd, tmp_path), 2, "sidecar nested deeper than")
    huge = _copy(base_log, tmp_path / "huge" / "run.log", lines, sidecar=False)
    with open(huge.with_name("run.log.json"), "wb") as fh:
        fh.truncate(300 * 2**20)  # sparse: 300 MB of NUL bytes
    c = cli(["report", str(huge), "--no-figures"], tmp_path)
    _one_line_error(c, 2, "sidecar refused", "314572800 bytes")
    assert c.peak_rss_mb < SMALL_RSS_MB


def _tiled(base_log: Path, dst: Path, copies: int) -> Path:
    """``copies`` copies of the log one after the other, each later by the log's length."""
    lines = base_log.read_text().splitlines(keepends=True)
    stamps = [round(_t(ln) * 1e6) for ln in lines]
    span = stamps[-1] - stamps[0] + 1000
    dst.parent.mkdir(parents=True, exist_ok=True)
    with open(dst, "w") as fh:
        for c in range(copies):
            fh.write(
                "".join(
                    f"({(us + c * span) / 1e6:017.6f}){ln[19:]}" for us, ln in zip(stamps, lines, strict=True)
                )
            )
    return dst


def test_logs_of_several_runs_joined_are_refused_in_bounded_memory(base_log: Path, tmp_path: Path) -> None:
    """The 2 GB row scaled down: 160 runs joined (40 MB), read in chunks (its files exceed
    ``STREAM_ABOVE_BYTES``) and refused at the first CycleCount that runs back — one line, its
    peak RSS that of a short report (before: refused at the cap of decoded values)."""
    long = _tiled(base_log, tmp_path / "long" / "run.log", 160)
    assert long.stat().st_size > 35e6
    small = cli(["report", str(base_log), "--no-figures", "--out", str(tmp_path / "s")], tmp_path)
    assert small.rc == 0, small.err
    prelude = "import ehpss_hil.limits as L; L.MAX_LOG_VALUES = 200_000"
    c = cli(["report", str(long), "--no-figures", "--out", str(tmp_path / "l")], tmp_path, prelude)
    _one_line_error(c, 2, "CycleCount jumps by 64337 samples after sample 1199", "several runs joined")
    assert c.peak_rss_mb < small.peak_rss_mb + 15


def test_a_report_past_the_sample_cap_is_streamed(base_log: Path, tmp_path: Path) -> None:
    """Beyond ``MAX_LOG_SAMPLES`` (scaled down to 1000: the log has 1200) the log is read in
    chunks of 500 commands: the same metrics as read whole."""
    whole = cli(["report", str(base_log), "--no-figures", "--out", str(tmp_path / "w")], tmp_path)
    prelude = "import ehpss_hil.limits as L; L.MAX_LOG_SAMPLES = 1000"
    c = cli(["report", str(base_log), "--no-figures", "--out", str(tmp_path / "r")], tmp_path, prelude)
    assert whole.rc == 0 and c.rc == 0, c.err
    assert "read in chunks: metrics use every sample (1200)" in c.out, c.out
    rms = [ln for ln in c.out.splitlines() if ln.startswith("RMS error")]
    assert rms and rms == [ln for ln in whole.out.splitlines() if ln.startswith("RMS error")]
    a = json.loads((tmp_path / "w" / "metrics.json").read_text())[0]
    b = json.loads((tmp_path / "r" / "metrics.json").read_text())[0]
    assert a["events"] == b["events"] and a["switches"] == b["switches"]
    assert a["rms_error_m"] == pytest.approx(b["rms_error_m"], rel=1e-12)


def _with_foreign_tail(base_log: Path, dst: Path, n: int) -> Path:
    """The log followed by ``n`` frames of an ID outside the DBC (7FF), 10 µs apart."""
    lines = base_log.read_text().splitlines(keepends=True)
    t = _t(lines[-1])
    tail = "".join(f"({t + 1e-5 * (i + 1):017.6f}) vcan0 7FF#0011223344556677\n" for i in range(n))
    return _copy(base_log, dst, [*lines, tail])


def test_replay_streams_a_long_log(base_log: Path, tmp_path: Path) -> None:
    """300 000 more frames (12 MB) cost the replay no memory: it no longer lists and sorts
    every frame (before: ≈ 0.6 kB per frame held)."""
    small = cli(["replay", str(base_log)], tmp_path)
    assert small.rc == 0 and "identical" in small.out, small.err
    long = _with_foreign_tail(base_log, tmp_path / "tail" / "run.log", 300_000)
    c = cli(["replay", str(long)], tmp_path)
    assert c.rc == 0 and "identical" in c.out, c.err
    assert c.peak_rss_mb < small.peak_rss_mb + 15


def test_a_growing_log_is_read_up_to_its_size_at_open(base_log: Path, tmp_path: Path) -> None:
    """A log another process appends to for ever (≈ 10 000 lines/s): replay and report end
    (before: read until out of memory)."""
    log = _with_foreign_tail(base_log, tmp_path / "grow" / "run.log", 0)
    writer = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\n"
            "t = 2e9\n"
            "with open(sys.argv[1], 'a') as fh:\n"
            "    while True:\n"
            "        for _ in range(100):\n"
            "            t += 1e-5\n"
            "            fh.write(f'({t:017.6f}) vcan0 7FF#00\\n')\n"
            "        fh.flush()\n"
            "        time.sleep(0.01)\n",
            str(log),
        ]
    )
    try:
        size0 = log.stat().st_size
        while log.stat().st_size < size0 + 10_000:  # the writer is running
            assert writer.poll() is None
            time.sleep(0.01)
        c = cli(["replay", str(log)], tmp_path)
        assert c.rc == 0 and "identical" in c.out, c.err
        c = cli(["report", str(log), "--no-figures", "--out", str(tmp_path / "r")], tmp_path)
        assert c.rc == 0 and "RMS error" in c.out, c.err
    finally:
        writer.kill()
        writer.wait()


def _stepped(base_log: Path, dst: Path, step_s: float) -> Path:
    lines = base_log.read_text().splitlines(keepends=True)
    half = len(lines) // 2
    out = lines[:half] + [_retimed(ln, _t(ln) + step_s) for ln in lines[half:]]
    return _copy(base_log, dst, out)


def test_a_half_second_step_back_is_undone_and_noted(base_log: Path, tmp_path: Path) -> None:
    """Before: RMS 0.6 → 600 µm without a note (steps were found above 0.5 s only)."""
    clean = log_metrics(load_log_run(base_log)).run
    for step, words in ((-0.5, "clock stepped -0.500 s"), (-0.05, "clock stepped -0.050 s")):
        run = load_log_run(_stepped(base_log, tmp_path / f"s{step}" / "run.log", step))
        assert any(words in n for n in run.notes), run.notes
        m = log_metrics(run).run
        assert m is not None and clean is not None and m.rms_error_m == clean.rms_error_m


def test_a_step_too_small_to_undo_is_noted(base_log: Path, tmp_path: Path) -> None:
    run = load_log_run(_stepped(base_log, tmp_path / "small" / "run.log", -0.005))
    assert any("run back by up to" in n and "left as logged" in n for n in run.notes), run.notes


# ---- item 6: the environment's limits are one line ----------------------------------------------
def test_a_small_address_space_is_one_line(base_log: Path, tmp_path: Path) -> None:
    """``ulimit -v 100000``: before, a MemoryError traceback while the command's module loaded."""
    c = cli(
        ["report", str(base_log), "--no-figures", "--out", str(tmp_path / "r")],
        tmp_path,
        rlimits={resource.RLIMIT_AS: 100_000 * 1024},
    )
    _one_line_error(c, 1, "out of memory", "address-space limit")


def test_run_out_of_file_descriptors_is_one_line(tmp_path: Path) -> None:
    """``ehpss-hil run`` under ``ulimit -n 8``: before, an OSError traceback."""
    from ehpss_hil import PROJECT_ROOT

    sc = PROJECT_ROOT / "scenarios" / "fault-free.yaml"
    c = cli(["run", str(sc), "--out", str(tmp_path / "run")], tmp_path, rlimits={resource.RLIMIT_NOFILE: 8})
    assert c.rc == 1 and "Traceback" not in c.err, c.err
    assert c.err_lines[-1].startswith("ehpss-hil run: error: Too many open files; open-file limit 8")


# ---- the components ------------------------------------------------------------------------------
def test_time_order_sorts_swaps_flushes_at_a_step_back_and_refuses_a_shuffle(tmp_path: Path) -> None:
    order: TimeOrder[int] = TimeOrder(tmp_path / "x.log", window=4, max_behind=2)
    got: list[int] = []
    for t in (1.0, 3.0, 2.0, 4.0, 5.0, 6.0, 7.0, 8.0, 0.5, 0.6, 0.7):
        got += order.push(t, int(t * 10))
    got += order.drain()
    # swaps sorted; at the step back (0.5) the held frames come first, then the late ones
    assert got == [10, 20, 30, 40, 50, 60, 70, 80, 5, 6, 7]
    assert order.behind == 1
    with pytest.raises(OutOfOrderError, match="not in time order"):
        for t in range(100, 0, -1):
            order.push(float(t), t)


def test_figures_of_a_long_run_keep_every_error_peak(base_log: Path) -> None:
    run = load_log_run(base_log)
    n = len(run.result.t_s)
    small = thinned(run, max_samples=100)
    assert len(small.result.t_s) <= 100 and small.result.index.shape == (len(small.result.t_s), 16)
    err, err_small = run.result.error_m, small.result.error_m
    assert np.nanmax(np.abs(err_small)) == np.nanmax(np.abs(err))
    assert thinned(run, max_samples=n) is run
