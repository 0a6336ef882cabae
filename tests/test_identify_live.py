"""``ehpss-hil identify -c``: the experiment run by the daemon's loop against the real emulator —
in-process over python-can ``virtual`` (both in lockstep), and as two processes on
``udp_multicast`` inside ``unshare --net``."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import can
import numpy as np
import pytest
from _proc import EHPSS_HIL, EMU_CFG_PATH, FIRMWARE_SIM, ROOT, Proc

from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason
from ehpss_hil.codec import FrameCodec
from ehpss_hil.control.base import Measurement
from ehpss_hil.control.registry import make_controller
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.identify.excitation import Excitation
from ehpss_hil.identify.experiment import ExperimentAborted, Record, experiment_scenario
from ehpss_hil.identify.fit import fit
from ehpss_hil.identify.live import ExcitationController
from ehpss_hil.identify.report import truth_of
from ehpss_hil.physics.load import load_params
from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.loop_run import run_lockstep
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.scenario import load_scenario
from firmware_sim.process import OWN_FRAMES as EMU_FRAMES
from firmware_sim.process import EmulatorOptions, EmulatorProcess

PLANT = ROOT / "scenarios" / "identify" / "kq075.yaml"
NETNS_SKIP = netns_unavailable_reason()


def _run_in_process(exc: Excitation, channel: str) -> ExcitationController:
    sc = experiment_scenario(load_scenario(PLANT), exc)
    params = load_params()
    eb = can.Bus(interface="virtual", channel=channel)
    cb = can.Bus(interface="virtual", channel=channel)
    try:
        emu = EmulatorProcess(
            PlantEmulation(params, sc), FrameIO(eb, FrameCodec(), EMU_FRAMES), EmulatorOptions()
        )
        ctrl = ExcitationController(make_controller("nrc", params, sc.sample_time_s), exc, sc.sample_time_s)
        loop = ControllerLoop(
            ctrl, FrameIO(cb, FrameCodec(), OWN_FRAMES), sc.reference, LoopOptions(lockstep_idle_s=0.5)
        )
        th = threading.Thread(target=run_lockstep, args=(loop, StopFlag(), sc.n_samples))
        th.start()
        assert emu.run_lockstep(StopFlag(), sc.n_samples)
        th.join()
        assert loop.cycles == sc.n_samples
    finally:
        eb.shutdown()
        cb.shutdown()
    return ctrl


def test_the_daemon_loop_identifies_the_emulated_plant() -> None:
    rec: Record = _run_in_process(Excitation(), "identify-live").record()
    res = fit(rec, load_params())
    truth = load_scenario(PLANT).plant.plant_params(load_params().plant)
    assert truth.flow_gain_1_s3 == pytest.approx(0.75 * load_params().plant.flow_gain_1_s3)
    for name in ("velocity_gain_1_s", "omega_h_rad_s", "omega_sv_rad_s", "valve_static_gain_m_per_a"):
        assert res.estimate(name).value == pytest.approx(truth_of(truth, name), rel=0.05), name
    for name in ("zeta_h", "zeta_sv"):
        assert res.estimate(name).value == pytest.approx(truth_of(truth, name), rel=0.25), name


def test_a_crossed_limit_on_the_bus_goes_fail_safe_and_names_it() -> None:
    ctrl = _run_in_process(Excitation(travel_limit_m=1e-5), "identify-live-limit")
    assert "travel" in ctrl.reason
    with pytest.raises(ExperimentAborted, match="fail-safe"):
        ctrl.record()


def test_the_record_follows_the_sensors_sample_clock_not_the_cycles() -> None:
    """Cycles that find no pair, then two (one superseded, handed to ``observe``), and a lost
    sample (``samples`` 2): each sample lands in its own row of the sample clock."""
    params = load_params()
    ctrl = ExcitationController(make_controller("nrc", params, 1e-3), Excitation(), 1e-3)

    def meas(position_m: float, samples: int, fresh: bool = True) -> Measurement:
        return Measurement(position_m=position_m, fresh=fresh, samples=samples)

    ctrl.step(meas(1e-6, 0))  # sample 0 (counter unknown: the cycle)
    ctrl.step(meas(0.0, 0, fresh=False))  # cycle 1: no pair
    ctrl.observe(meas(2e-6, 1))  # sample 1, superseded in cycle 2
    ctrl.step(meas(3e-6, 1))  # sample 2
    ctrl.step(meas(5e-6, 2))  # sample 4 (sample 3 lost)
    rows = ctrl._rows[:6, 0]
    np.testing.assert_array_equal(rows[[0, 1, 2, 4]], [1e-6, 2e-6, 3e-6, 5e-6])
    assert np.isnan(rows[[3, 5]]).all() and ctrl.samples_recorded() == 4
    assert ctrl.last_sample_s() == pytest.approx(4e-3)


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_identify_c_with_the_emulator_process_writes_params(tmp_path: Path) -> None:
    out = tmp_path / "P.yaml"
    with PrivateNetns() as ns:
        cmd = ["identify", "-c", str(ROOT / "configs" / "controller.yaml"), "--lockstep", "--out", str(out)]
        ident = Proc(ns.prefix() + EHPSS_HIL + cmd)
        emu = None
        try:
            assert ident.wait_for("(lockstep)"), ident.text
            emu_args = [
                "-c",
                EMU_CFG_PATH,
                "--mode",
                "lockstep",
                "--duration",
                "3.0",
                "--scenario",
                str(PLANT),
            ]
            emu = Proc(ns.prefix() + FIRMWARE_SIM + emu_args)
            assert emu.wait() == 0, emu.text
            assert ident.wait() == 0, ident.text
        finally:
            ident.kill()
            if emu is not None:
                emu.kill()
    got = load_params(out).plant
    assert got.flow_gain_1_s3 == pytest.approx(7.7325e7, rel=0.05)


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_a_stalled_realtime_loop_ends_identify_with_the_watchdogs_reason(tmp_path: Path) -> None:
    """``identify -c`` in realtime, the loop stopped (SIGSTOP) for 0.2 s as a loaded host stalls
    it: the watchdog trips, and the one error line names the trip and what the host needs
    instead of asking whether the emulator is on the bus; nothing is written."""
    out = tmp_path / "P.yaml"
    with PrivateNetns() as ns:
        emu_args = ["-c", EMU_CFG_PATH, "--scenario", str(PLANT), "--duration", "600"]
        emu = Proc(ns.prefix() + FIRMWARE_SIM + emu_args)
        ident = None
        try:
            assert emu.wait_for("realtime on"), emu.text
            cmd = ["identify", "-c", str(ROOT / "configs" / "controller.yaml"), "--out", str(out)]
            ident = Proc(ns.prefix() + EHPSS_HIL + cmd)
            assert ident.wait_for("first sensor data", limit_s=120.0), ident.text
            os.kill(ident.p.pid, signal.SIGSTOP)
            time.sleep(0.2)  # the stall, not a timing assertion
            os.kill(ident.p.pid, signal.SIGCONT)
            assert ident.wait(limit_s=120.0) == 1, ident.text
        finally:
            if ident is not None:
                ident.kill()
            emu.kill()
    err = "".join(ident.err)
    assert "realtime without SCHED_FIFO" in err
    assert "watchdog tripped" in err and "--rt-priority" in err, err
    assert "is the valve or the emulator on the bus" not in err
    assert not out.exists()
