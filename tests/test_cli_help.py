"""The help texts name every sub-command from its registry (so they cannot drift), and every
``ehpss-hil bench`` exits 1 when one of its targets fails (one mechanism: the Scorecard each
bench returns)."""

from __future__ import annotations

import subprocess
from pathlib import Path

from _proc import EHPSS_HIL, ENV, ROOT

from ehpss_hil import bench as bench_pkg
from ehpss_hil.bench import BENCHES
from ehpss_hil.bench.common import Scorecard
from ehpss_hil.commands import COMMANDS
from ehpss_hil.commands.bench import discover


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*EHPSS_HIL, *args], cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=600, check=False
    )


def test_the_bench_registry_names_exactly_the_bench_modules() -> None:
    assert sorted(BENCHES) == sorted(m.NAME for m in discover(bench_pkg))


def test_top_level_help_lists_every_command_and_every_bench() -> None:
    r = _cli("--help")
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())  # argparse wraps lines
    for name in COMMANDS:
        assert f" {name} " in text, name
    bench_line = text.split(" bench ", 1)[1].split(" campaign ", 1)[0]
    for name in BENCHES:
        assert name in bench_line, (name, bench_line)


def test_bench_help_lists_every_bench_and_run_mode_has_a_help_text() -> None:
    r = _cli("bench", "--help")
    assert r.returncode == 0, r.stderr
    listed = {line.split()[0] for line in r.stdout.splitlines() if line.startswith("    ") and line.split()}
    assert set(BENCHES) <= listed, listed
    r = _cli("run", "--help")
    options = " ".join(r.stdout.split()).split("options:", 1)[1]
    mode = options.split("--mode {", 1)[1].split("--interface", 1)[0]
    assert "control law" in mode, mode


def test_scorecard_exit_code_follows_the_failed_targets() -> None:
    card = Scorecard()
    assert card.mark(None, "info") == "" and card.exit_code() == 0
    assert card.mark(True, "a") == "PASS" and card.exit_code() == 0
    assert card.mark(False, "b 3 µs") == "FAIL" and card.exit_code() == 1
    assert card.line("x") == "bench x: 1 of 2 target(s) FAIL: b 3 µs"


def test_a_bench_whose_target_fails_exits_1(tmp_path: Path) -> None:
    """``bench bus`` on a controller config at 2 kHz on 1 Mbit/s: its own cell is over the bus
    budget (88 %) → FAIL, exit 1; the shipped config passes, exit 0."""
    cfg = tmp_path / "controller-2k.yaml"
    text = (ROOT / "configs" / "controller.yaml").read_text()
    assert "rate_hz: 1000" in text
    cfg.write_text(
        text.replace("rate_hz: 1000", "rate_hz: 2000")
        .replace("params: ", f"params: {ROOT}/configs/")
        .replace("dbc: ../", f"dbc: {ROOT}/")
    )
    bad = _cli("bench", "bus", "--config", str(cfg))
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert "88.0% FAIL" in bad.stdout
    assert bad.stdout.splitlines()[-1].startswith("bench bus: 1 of 1 target(s) FAIL: native")
    good = _cli("bench", "bus", "--config", str(ROOT / "configs" / "controller.yaml"))
    assert good.returncode == 0, good.stdout + good.stderr
    assert good.stdout.splitlines()[-1] == "bench bus: 1 target(s) PASS"
