"""``ehpss-hil run`` with real processes on the embedded bus (private network namespace): the
lockstep run gives the offline simulation's commands and metrics; a realtime run of a sensor
drift meets a bound that the unreconfigured loop misses by far. No timing is asserted."""

from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from _proc import STARTUP_LIMIT_S, lockstep_plan
from _scenarios import short_scenario_yaml

from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.errors import ProcessFailedError
from ehpss_hil.orchestrate import RunPlan, check_exit_codes, execute
from ehpss_hil.replay.engine import replay_log
from ehpss_hil.report.logdata import load_log_run
from ehpss_hil.run_metrics import metrics_from_run
from ehpss_hil.scenario import load_scenario
from ehpss_hil.sim.lockstep import run_scenario

NETNS_SKIP = netns_unavailable_reason()
pytestmark = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")

DRIFT = short_scenario_yaml("short-drift", 0.8, "{t_s: 0.3, k_dft: 0.5}")


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("run") / "short-drift.yaml"
    p.write_text(DRIFT)
    return p


def test_lockstep_run_gives_the_simulation_commands_and_metrics(scenario: Path, tmp_path: Path) -> None:
    out = tmp_path / "lockstep"
    check_exit_codes(execute(lockstep_plan(scenario, out, "mmac")))
    row = metrics_from_run(out)
    sim = run_scenario(load_scenario(scenario), "mmac")
    logged = load_log_run(out / "bus.log")
    cmd = logged.commanded_current_a
    n = len(sim.current_a) - 1
    assert len(cmd) >= n
    # command k is applied over [k+1, k+2) (one sample of transport delay, the scenario's):
    # the sim's applied current one sample later, bit for bit
    assert sim.current_a[0] == 0.0
    assert np.array_equal(cmd[:n], sim.current_a[1 : n + 1])
    sim_rms = float(np.sqrt(np.mean((sim.x_true_m - sim.y_m_m) ** 2)))
    assert row["rms_error_m"] == pytest.approx(sim_rms, rel=0.02, abs=0.05e-6)  # truth: 0.1 µm LSB
    assert row["rms_error_m"] < 5e-6
    assert replay_log(out / "controller.log").identical
    # the logs carry their own metadata: moved away from the run, they still give the run
    moved = tmp_path / "moved"
    moved.mkdir()
    for f in ("emulator.log", "emulator.log.json", "controller.log", "controller.log.json"):
        shutil.copy(out / f, moved / f)
    side = json.loads((moved / "emulator.log.json").read_text())
    assert isinstance(side["scenario"], dict) and isinstance(side["config"], dict)
    emu = load_log_run(moved / "emulator.log")
    assert emu.scenario is not None and emu.scenario.events == load_scenario(scenario).events
    ctl = load_log_run(moved / "controller.log")
    assert ctl.has_reference and ctl.result.ts_s == 1e-3 and ctl.result.controller == "mmac"


@pytest.mark.alone
@pytest.mark.parametrize(("mode", "bound_m", "above"), [("mmac", 15e-6, False), ("nrc", 100e-6, True)])
def test_realtime_drift_run(scenario: Path, tmp_path: Path, mode: str, bound_m: float, above: bool) -> None:
    """Sensor gain 0.5 at 0.3 s: ``mmac`` stays within 15 µm RMS on the real-time bus (0.67–2.9
    µm measured, offline 0.64; in this 0.8 s run a start-up stall of a loaded host alone adds up
    to ~3 µm; the failures this guards against gave 28–263 µm: x̂ off the sensor's sample clock,
    a false flow-gain decision after a stall), ``nrc`` tracks x_d/0.5 (510 µm measured)."""
    out = tmp_path / mode
    check_exit_codes(
        execute(RunPlan(scenario_path=scenario, mode=mode, out_dir=out, startup_timeout_s=STARTUP_LIMIT_S))
    )
    row = metrics_from_run(out)
    assert row["unavailable"] == [] and len(row["events"]) == 1
    kept = row["realtime_valid"]
    if above or not kept:
        # nrc's failure to track is load-independent; mmac's bound holds for a run that kept its
        # clock (on a starved host the loop's own counters say it did not: then it is reported,
        # not judged — the fail-safe and no-runaway behaviour is what the stall tests assert)
        if not above:
            import warnings

            warnings.warn(
                f"realtime drift run did not keep time ({row['realtime_reasons']}): RMS "
                f"{row['rms_error_m'] * 1e6:.1f} um not judged",
                stacklevel=1,
            )
            return
    assert (row["rms_error_m"] > bound_m) if above else (row["rms_error_m"] < bound_m), row


def test_a_run_stopped_before_the_scenario_ends_fails_naming_it(tmp_path: Path) -> None:
    """A 5-s realtime scenario with a 1-s finish timeout: the emulator is stopped, the run fails
    (its logs end early), instead of passing with a short log."""
    sc = tmp_path / "long.yaml"
    sc.write_text(short_scenario_yaml("long", 5.0, "{t_s: 4.0, k_loe: 0.5}"))
    out = tmp_path / "cut"
    res = execute(
        RunPlan(scenario_path=sc, out_dir=out, finish_timeout_s=1.0, startup_timeout_s=STARTUP_LIMIT_S)
    )
    assert res.unfinished_after_s == 1.0
    with pytest.raises(ProcessFailedError, match="had not finished the scenario after 1 s"):
        check_exit_codes(res)


def _pause_the_emulator(out: Path, seconds: float, done: threading.Event, paused: list[int]) -> None:
    """SIGSTOP the run's emulator (found by its log path in /proc) once it has sent frames,
    for ``seconds``, then SIGCONT it: a loaded host holding the process back. Its pid goes to
    ``paused``."""
    log = str(out / "emulator.log")
    deadline = time.monotonic() + STARTUP_LIMIT_S
    while time.monotonic() < deadline and not done.is_set():
        for d in Path("/proc").iterdir():
            try:
                cmd = (d / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            started = (out / "emulator.log").exists() and (out / "emulator.log").stat().st_size > 0
            if b"firmware_sim.cli" in cmd and log.encode() in cmd and started:
                pid = int(d.name)
                os.kill(pid, signal.SIGSTOP)
                time.sleep(seconds)
                os.kill(pid, signal.SIGCONT)
                paused.append(pid)
                return
        time.sleep(0.01)


def test_a_lockstep_run_survives_an_emulator_held_back_for_seconds(scenario: Path, tmp_path: Path) -> None:
    """The emulator stopped for 3 s mid-run (SIGSTOP): the controller waits for its next sensor
    frames as long as the emulator waits for a command (``LOCKSTEP_PATIENCE_S``). It used to end
    after 2 s of silence (exit 0), and the emulator then gave up waiting for the command of its
    next sample (exit 1: a CI run in two loaded VMs at once)."""
    out = tmp_path / "held"
    done = threading.Event()
    paused: list[int] = []
    pauser = threading.Thread(target=_pause_the_emulator, args=(out, 3.0, done, paused))
    pauser.start()
    try:
        res = execute(lockstep_plan(scenario, out, "nrc"))
    finally:
        done.set()
        pauser.join()
    assert paused, "the emulator was never held back"
    check_exit_codes(res)
    sc = load_scenario(scenario)
    assert len(load_log_run(out / "bus.log").commanded_current_a) >= sc.n_samples
