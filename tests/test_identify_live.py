"""``ehpss-hil identify -c``: the experiment run by the daemon's loop against the real emulator —
in-process over python-can ``virtual`` (both in lockstep), and as two processes on
``udp_multicast`` inside ``unshare --net``."""

from __future__ import annotations

import threading
from pathlib import Path

import can
import pytest
from _proc import EHPSS_HIL, EMU_CFG_PATH, FIRMWARE_SIM, ROOT, Proc

from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason
from ehpss_hil.codec import FrameCodec
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
