"""``ehpss-hil bringup``: the checks before the first enable against the emulator — the daemon's
loop in-process over python-can ``virtual`` (both in lockstep), and as two processes on
``udp_multicast`` inside ``unshare --net``: a correctly wired valve passes every check; a valve
with its coil, its spool LVDT or its position sensor reversed (``firmware-sim --reverse``) is
refused with one line naming what is reversed (exit 3)."""

from __future__ import annotations

import threading

import can
import pytest
from _proc import EHPSS_HIL, EMU_CFG_PATH, FIRMWARE_SIM, ROOT, Proc

from ehpss_hil.bringup.judge import judge
from ehpss_hil.bringup.sequence import BringupController, BringupPlan
from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason
from ehpss_hil.codec import FrameCodec
from ehpss_hil.physics.load import load_params
from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.loop_run import run_lockstep
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.scenario import Reference, Scenario
from firmware_sim.process import OWN_FRAMES as EMU_FRAMES
from firmware_sim.process import EmulatorOptions, EmulatorProcess
from firmware_sim.wiring import make_emulation

NETNS_SKIP = netns_unavailable_reason()
TS_S = 1e-3
PLAN = BringupPlan()


def _run_in_process(reverse: list[str], channel: str, plan: BringupPlan = PLAN) -> BringupController:
    """The sequence through the daemon's loop against the emulator's process loop, lockstep."""
    params = load_params()
    n = sum(plan.phase_samples(TS_S))
    sc = Scenario(name="bringup", duration_s=n * TS_S, sample_time_s=TS_S)
    eb = can.Bus(interface="virtual", channel=channel)
    cb = can.Bus(interface="virtual", channel=channel)
    try:
        emu = EmulatorProcess(
            make_emulation(params, sc, reverse), FrameIO(eb, FrameCodec(), EMU_FRAMES), EmulatorOptions()
        )
        ctrl = BringupController(plan, plan.current_share * params.plant.stroke_current_a, TS_S)
        loop = ControllerLoop(
            ctrl, FrameIO(cb, FrameCodec(), OWN_FRAMES), Reference(), LoopOptions(lockstep_idle_s=0.5)
        )
        th = threading.Thread(target=run_lockstep, args=(loop, StopFlag(), n))
        th.start()
        assert emu.run_lockstep(StopFlag(), n)
        th.join()
    finally:
        eb.shutdown()
        cb.shutdown()
    return ctrl


def test_a_correctly_wired_valve_passes_every_check() -> None:
    ctrl = _run_in_process([], "bringup-ok")
    found = {f.name: f for f in judge(ctrl, load_params().plant)}
    assert [f.name for f in found.values()] == ["sensors", "zero", "echo", "polarity"]
    assert all(f.ok for f in found.values()), found
    assert found["polarity"].text.startswith("as expected: +60.6 µA moved the spool +")
    # the spool's steady +61 µA response is K_sv·I = 1 mm (the params' model), within the noise
    plus = slice(ctrl.bounds[0] + 100, ctrl.bounds[1])
    assert ctrl.rows[plus, 1].mean() == pytest.approx(1e-3, rel=0.05)
    assert ctrl.commands[ctrl.bounds[0] : ctrl.bounds[1]].max() == pytest.approx(
        0.1 * load_params().plant.stroke_current_a, rel=1e-12
    )


@pytest.mark.parametrize(
    ("reverse", "finding"),
    [
        (
            ["current"],
            "the valve's drive is reversed (coil or amplifier polarity): +60.6 µA moved the spool -",
        ),
        (["spool"], "the spool position (LVDT) reads reversed: +60.6 µA moved the spool -"),
        (["position"], "the piston position sensor reads reversed: +60.6 µA moved the spool +"),
    ],
)
def test_a_reversed_signal_is_named(reverse: list[str], finding: str) -> None:
    ctrl = _run_in_process(reverse, f"bringup-{reverse[0]}")
    found = {f.name: f for f in judge(ctrl, load_params().plant)}
    assert not found["polarity"].ok and found["polarity"].text.startswith(finding), found["polarity"]
    assert found["echo"].ok  # the amplifier reports what it was told, whatever the coil does


def test_a_crossed_travel_limit_goes_fail_safe_and_names_it() -> None:
    ctrl = _run_in_process([], "bringup-limit", BringupPlan(travel_limit_m=1e-4))
    assert (
        ctrl.reason.startswith("bring-up stopped in fail-safe at t = ")
        and "travel limit 0.1 mm" in ctrl.reason
    )
    after = ctrl.commands[int(ctrl.reason.split("t = ")[1].split(" s")[0].replace(".", "")) + 1 :]
    assert not after.any()  # 0 A from the crossing on
    found = judge(ctrl, load_params().plant)
    assert [(f.name, f.ok) for f in found] == [("sensors", True), ("limits", False)]


def _bringup_processes(reverse: list[str]) -> tuple[Proc, Proc]:
    cfg = str(ROOT / "configs" / "controller.yaml")
    with PrivateNetns() as ns:
        bring = Proc(ns.prefix() + EHPSS_HIL + ["bringup", "-c", cfg, "--lockstep"])
        emu = None
        try:
            assert bring.wait_for("(lockstep)"), bring.text
            duration = str(round(sum(PLAN.phase_samples(TS_S)) * TS_S + 0.05, 3))
            args = ["-c", EMU_CFG_PATH, "--mode", "lockstep", "--duration", duration]
            emu = Proc(ns.prefix() + FIRMWARE_SIM + args + [a for r in reverse for a in ("--reverse", r)])
            emu.wait()
            bring.wait()
        finally:
            bring.kill()
            if emu is not None:
                emu.kill()
    return bring, emu


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_bringup_passes_against_the_emulator_process() -> None:
    bring, emu = _bringup_processes([])
    assert emu.p.returncode == 0, emu.text
    assert bring.p.returncode == 0, bring.text
    out = "".join(bring.out)
    assert "bit rate: udp_multicast:239.74.163.2 exposes none; bus.bitrate 1000000 not checked" in out
    assert "polarity  PASS  as expected" in out and "every check passed" in out


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_bringup_refuses_a_reversed_coil_in_one_line_exit_3() -> None:
    bring, _ = _bringup_processes(["current"])
    assert bring.p.returncode == 3, bring.text
    errors = [line for line in bring.err if "ERROR" in line or "error" in line]
    assert len(errors) == 1 and "Traceback" not in "".join(bring.err), bring.text
    assert (
        "bring-up refused: polarity: the valve's drive is reversed (coil or amplifier polarity)" in errors[0]
    )
