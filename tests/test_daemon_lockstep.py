"""The daemon loop in lockstep (one cycle per received sensor pair), in-process over python-can
``virtual``: against the real emulator with the real ``mmac`` law, and with a test peer for
duplicate pairs and lost samples."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import can
import pytest
from _daemon_rig import Rig

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.physics.load import load_params
from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.lifecycle import State
from ehpss_hil.runtime.loop_run import run_lockstep
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.scenario import Reference, Scenario


@pytest.fixture
def rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    r = Rig(request.node.name)
    yield r
    r.close()


def test_lockstep_with_emulator_and_mmac() -> None:
    """The real control law against the emulator, both in lockstep: one answer per sample."""
    from ehpss_hil.control.registry import make_controller
    from ehpss_hil.emulation import PlantEmulation
    from firmware_sim.process import OWN_FRAMES as EMU_FRAMES
    from firmware_sim.process import EmulatorOptions, EmulatorProcess

    sc = Scenario(name="ls", duration_s=0.5)
    params = load_params()
    eb = can.Bus(interface="virtual", channel="daemon-lockstep")
    cb = can.Bus(interface="virtual", channel="daemon-lockstep")
    try:
        emu = EmulatorProcess(
            PlantEmulation(params, sc), FrameIO(eb, FrameCodec(), EMU_FRAMES), EmulatorOptions()
        )
        loop = ControllerLoop(
            make_controller("mmac", params, 1e-3, None, sc.reference),
            FrameIO(cb, FrameCodec(), OWN_FRAMES),
            sc.reference,
            LoopOptions(lockstep_idle_s=0.5),
        )
        th = threading.Thread(target=run_lockstep, args=(loop, StopFlag(), sc.n_samples))
        th.start()
        assert emu.run_lockstep(StopFlag(), sc.n_samples)
        th.join()
        assert loop.cycles == sc.n_samples == emu.hold.accepted
        assert loop.life.state is State.ACTIVE and emu.hold.timeouts == 0
        assert abs(emu.emu.plant.position_m) < 2e-3
    finally:
        eb.shutdown()
        cb.shutdown()


def _lockstep_run(rig: Rig, feed: Any) -> list[dict[str, Any]]:
    """Run the lockstep loop until the bus is idle for 0.3 s while ``feed()`` sends frames;
    returns the VALVE_CMDs it answered with."""
    loop = ControllerLoop(
        rig.ctrl, rig.loop.io, Reference(kind="step", amplitude_m=1e-3), LoopOptions(lockstep_idle_s=0.3)
    )
    rig.loop = loop
    th = threading.Thread(target=run_lockstep, args=(loop, StopFlag()))
    th.start()
    feed()
    th.join(timeout=30)
    assert not th.is_alive()
    return rig.values_of("VALVE_CMD")


def test_lockstep_answers_a_duplicate_pair_never(rig: Rig) -> None:
    """A repeated sensor pair (same bytes) is counted REPEATED and gets no cycle: the law steps
    and answers once per distinct pair."""

    def feed() -> None:
        for i in range(3):
            pos = rig.sensors(1e-4 * i)
            if i == 1:
                rig.peer.send(pos)  # the same frames again
                rig.peer.send(rig.tx.encode("SENSOR_AUX", {"CoilCurrent": 1e-5}, counter=1))

    cmds = _lockstep_run(rig, feed)
    assert len(cmds) == 3 and rig.ctrl.steps == 3
    assert [c["CycleCount"] for c in cmds] == [0, 1, 2]
    assert rig.loop.codec.counts_by_name["SENSOR_POS"][Verdict.REPEATED] == 1


def test_lockstep_steps_over_lost_sensor_samples(rig: Rig) -> None:
    """Two sensor samples lost on the way (the counter jumps by 3): the law steps twice without
    data before the cycle, so the reference stays on the plant's sample clock."""

    def feed() -> None:
        rig.sensors()
        rig.sensors()
        for _ in range(2):
            rig.tx.skip("SENSOR_POS")
            rig.tx.skip("SENSOR_AUX")
        rig.sensors(3e-4)

    cmds = _lockstep_run(rig, feed)
    assert len(cmds) == 3 and rig.ctrl.steps == 5
    assert [c["CycleCount"] for c in cmds] == [0, 1, 4]
    assert rig.loop.k_active == 5 and rig.loop.skipped_periods == 2
