"""The one mapping of decoded frames onto the controller driver
(:meth:`~ehpss_hil.driver.ControllerDriver.take`): the same sensor and SETPOINT frames through
each of its users — the daemon's loop, replay, the sample log's bench and the simulator's two
transports — leave the same input in the driver: the values the DBC decodes, the E2E counter the
frame carries, the SETPOINT override the policy admits."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import can

from ehpss_hil.canlog import CandumpLogger
from ehpss_hil.codec import FrameCodec
from ehpss_hil.config import SetpointPolicy
from ehpss_hil.control.registry import make_controller
from ehpss_hil.control.tuning import ControlTuning
from ehpss_hil.driver import ControllerDriver
from ehpss_hil.emulation import SensorSample
from ehpss_hil.physics.faults import FaultState
from ehpss_hil.physics.load import load_params
from ehpss_hil.replay.engine import Replayer, ReplaySetup
from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.scenario import Reference, Scenario
from ehpss_hil.sim.samplelog import _Bench
from ehpss_hil.sim.transport import FramesTransport, QuantizeTransport

PARAMS = load_params()
TS_S = 1e-3
#: (position m, spool m, load pressure Pa, coil current A) per sample: off the DBC grid, both
#: signs; the position moves less than the piston can per sample (replay's rate check passes it)
SAMPLES = [
    (
        -1.23456789e-3 + 5.4321e-6 * math.sin(i),
        -3.3333333e-4 * math.cos(i),
        1.2345678e5 * (i - 9),
        0.0123456789 * (-1) ** i,
    )
    for i in range(21)
]
#: samples lost on the way (their counters move on: the receiver sees OK_SOME_LOST)
LOST = {4, 5, 13}
#: SETPOINT frames after the sensor pair of these samples: (Override, Position m)
SETPOINTS = {2: (True, 0.0123456789), 7: (True, 0.2), 11: (False, 0.0), 16: (True, -0.00987654321)}
POLICY = SetpointPolicy(enabled=True, max_abs_m=0.05, max_step_m=1.0)

Inputs = tuple[float, float, float, float, int, float | None]


def _inputs(drv: ControllerDriver) -> Inputs:
    m = drv.meas
    return (m.position_m, m.spool_m, m.load_pressure_pa, m.coil_current_a, drv.counter, drv.override_m)


def _sensor_frames(tx: FrameCodec, i: int) -> tuple[can.Message, can.Message]:
    pos, spool, pressure, coil = SAMPLES[i]
    return (
        tx.encode("SENSOR_POS", {"Position": pos, "Spool": spool}),
        tx.encode("SENSOR_AUX", {"LoadPressure": pressure, "CoilCurrent": coil, "ValveEnabled": 1}),
    )


def _frames() -> list[list[can.Message]]:
    """Per sample, the frames that arrive (none for a lost sample; SETPOINT after the pair)."""
    tx, out = FrameCodec(), []
    for i in range(len(SAMPLES)):
        pair = _sensor_frames(tx, i)  # a lost pair was sent: its counters moved on
        arrived = [] if i in LOST else list(pair)
        if i in SETPOINTS:
            override, x = SETPOINTS[i]
            arrived.append(tx.encode("SETPOINT", {"Override": int(override), "Position": x}))
        out.append(arrived)
    return out


def _expected(with_setpoints: bool) -> list[Inputs]:
    """What the DBC decodes (``FrameCodec.quantize``), the counter i mod 16, the admitted override."""
    q, out, last, override = FrameCodec(), [], None, None
    for i, (pos, spool, pressure, coil) in enumerate(SAMPLES):
        if i not in LOST:
            p = q.quantize("SENSOR_POS", {"Position": pos, "Spool": spool})
            a = q.quantize("SENSOR_AUX", {"LoadPressure": pressure, "CoilCurrent": coil})
            last = (p["Position"], p["Spool"], a["LoadPressure"], a["CoilCurrent"], i % 16)
        if with_setpoints and i in SETPOINTS:
            on, x = SETPOINTS[i]
            if not on:
                override = None
            elif abs(x) <= POLICY.max_abs_m:
                override = q.quantize("SETPOINT", {"Position": x})["Position"]
        assert last is not None
        out.append((*last, override))
    return out


def _per_sample(
    offer: Callable[[list[can.Message]], None], drv: Callable[[], ControllerDriver]
) -> list[Inputs]:
    got = []
    for arrived in _frames():
        offer(arrived)
        got.append(_inputs(drv()))
    return got


def test_the_daemon_loop_and_replay_give_the_driver_the_same_input() -> None:
    want = _expected(with_setpoints=True)
    assert len({w[5] for w in want}) == 3  # None, and two admitted overrides (one refused)
    bus = can.Bus(interface="virtual", channel="driver-mapping", receive_own_messages=False)
    try:
        ctrl = make_controller("nrc", PARAMS, TS_S)
        loop = ControllerLoop(
            ctrl, FrameIO(bus, FrameCodec(), OWN_FRAMES), Reference(), LoopOptions(setpoint=POLICY)
        )

        def loop_offer(fs: list[can.Message]) -> None:
            for f in fs:
                loop.on_frame(f)

        got_loop = _per_sample(loop_offer, lambda: loop.driver)
    finally:
        bus.shutdown()
    assert got_loop == want
    assert loop.setpoints.accepted == 3 and loop.setpoints.rejected == 1

    setup = ReplaySetup("nrc", TS_S, Reference(), ControlTuning(), PARAMS, "test", POLICY)
    rep = Replayer(setup, keep=1, lost_commands=False)

    def replay_offer(fs: list[can.Message]) -> None:
        for n, f in enumerate(fs):
            rep.frame(f, n)
        rep.feed(len(rep.pending))

    assert _per_sample(replay_offer, lambda: rep.driver) == want


def test_the_sample_log_and_the_simulators_transports_give_the_driver_the_same_input(
    tmp_path: Path,
) -> None:
    want = _expected(with_setpoints=False)
    ctrl = make_controller("nrc", PARAMS, TS_S)
    log = CandumpLogger(tmp_path / "bench.log", iface="vcan0")
    try:
        bench = _Bench(Scenario(name="map", duration_s=0.1), ctrl, PARAMS, log, False, 0.0, [0.0] * 100)
        got_bench = []
        for i, (pos, spool, pressure, coil) in enumerate(SAMPLES):
            if i in LOST:  # what the bench does for a sample its scenario loses
                bench.tx_emu.skip("SENSOR_POS")
                bench.tx_emu.skip("SENSOR_AUX")
            else:
                s = SensorSample(i, i * TS_S, pos, spool, pressure, coil, pos, spool, FaultState(), False)
                bench.sensors(s, i * TS_S)
            got_bench.append(_inputs(bench.drv))
    finally:
        log.close()
    assert got_bench == want

    for transport in (QuantizeTransport(FrameCodec()), FramesTransport(FrameCodec(), FrameCodec())):
        drv = ControllerDriver(make_controller("nrc", PARAMS, TS_S), lambda k: 0.0)
        got = []
        for i, (pos, spool, pressure, coil) in enumerate(SAMPLES):
            taken = transport.sensor(drv, i, pos, spool, pressure, coil, False, i in LOST)
            assert taken is (i not in LOST)
            got.append(_inputs(drv))
        assert got == want, type(transport).__name__


def test_sensors_is_position_then_aux_including_a_superseded_sample() -> None:
    """``ControllerDriver.sensors`` (the quantize transport's one call per sample) does what
    ``position`` then ``aux`` do: two mmac controllers, one fed each way, with every third
    cycle carrying two samples (the first superseded: held and observed before the step), give
    the same commands and end in the same driver and estimator state."""
    drivers = [
        ControllerDriver(make_controller("mmac", PARAMS, TS_S), lambda k: 1e-3 * math.sin(k / 9))
        for _ in "ab"
    ]
    a, b = drivers
    seen: list[list[tuple[float, int]]] = [[], []]  # per cycle: the command, the samples stepped
    k = 0
    for cycle in range(14):
        for _ in range(2 if cycle % 3 == 2 else 1):
            pos, spool, pressure, coil = SAMPLES[k % len(SAMPLES)]
            a.position(pos, spool, k & 0x0F)
            a.aux(coil, pressure)
            b.sensors(pos, spool, k & 0x0F, coil, pressure)
            k += 1
        for drv, out in zip(drivers, seen, strict=True):
            out.append((drv.step()[0], drv.meas.samples))
    assert seen[0] == seen[1] and len({c for c, _ in seen[0]}) > 5
    # the superseded sample was observed, so the step stands one sample on from it
    assert {n for _, n in seen[1][1:]} == {1}
    assert _inputs(a) == _inputs(b)
    ca, cb = a.controller, b.controller
    assert ca.xhat.x == cb.xhat.x and ca.valve.v == cb.valve.v  # type: ignore[attr-defined]
