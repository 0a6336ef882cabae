"""The emulator process in lockstep over python-can ``virtual`` equals the offline
:class:`PlantEmulation` step for step (same seed), fault onsets on the exact sample included."""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Iterator

import can
import numpy as np
import pytest

from ehpss_hil.codec import FrameCodec
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.physics.load import load_params
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.scenario import Event, Noise, Scenario
from firmware_sim.command_hold import CommandHold
from firmware_sim.process import OWN_FRAMES, EmulatorOptions, EmulatorProcess

N = 300
EVENT_K = (100, 180)
Law = Callable[[dict[str, float], int], float]


def _scenario(loss: float = 0.0, delay: int = 1) -> Scenario:
    return Scenario(
        name="lockstep-test",
        duration_s=N * 1e-3,
        sample_time_s=1e-3,
        seed=7,
        noise=Noise(position_m=1e-6, spool_m=1.5e-6, pressure_pa=1e4),
        frame_loss=loss,
        transport_delay_samples=delay,
        events=(Event(t_s=EVENT_K[0] * 1e-3, k_loe=0.5), Event(t_s=EVENT_K[1] * 1e-3, k_dft=0.8)),
    )


#: coil currents of the size the loop uses (~0.1 mA moves the piston ~1 mm at 5 rad/s)
RECORDED = 1e-4 * np.sin(2 * np.pi * np.arange(N) / 60.0) + 2e-5 * np.random.default_rng(3).normal(size=N)


def recorded_law(pos: dict[str, float], idx: int) -> float:
    """The recorded current sequence, indexed by the answered sensor pair (A)."""
    return float(RECORDED[idx])


def p_law(pos: dict[str, float], idx: int) -> float:
    """A deterministic function of the received sample only (works with lost frames) (A)."""
    return float(np.clip(1e-4 - 0.05 * pos["Position"], -1.0, 1.0))


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    a = can.Bus(interface="virtual", channel="lockstep-test")
    b = can.Bus(interface="virtual", channel="lockstep-test")
    yield a, b
    a.shutdown()
    b.shutdown()


def _client(bus: can.BusABC, law: Law, frames: list[can.Message]) -> None:
    """Answer every sensor pair with one VALVE_CMD; end when the bus stays quiet."""
    codec = FrameCodec()
    pos: dict[str, float] | None = None
    idx = 0
    while (msg := bus.recv(0.5)) is not None:
        frames.append(msg)
        d = codec.classify(msg)
        if d.name == "SENSOR_POS":
            pos = d.values
        elif d.name == "SENSOR_AUX" and pos is not None:
            u = law(pos, idx)
            idx += 1
            pos = None
            bus.send(codec.encode("VALVE_CMD", {"CurrentSetpoint": u, "Enable": 1}))


def _offline(sc: Scenario, law: Law) -> tuple[list[dict[str, float]], list[int]]:
    """The offline reference: the same PlantEmulation stepped directly, with the same hold
    (timeout) logic and transport delay; returns the quantized sensor values sent and the
    indices k at which sensor frames were sent."""
    codec = FrameCodec()
    emu = PlantEmulation(load_params(), sc)
    hold = CommandHold(10)
    delay = deque([0.0] * sc.transport_delay_samples)
    sent, ks, idx = [], [], 0
    for k in range(N):
        y = emu.measure()
        lost_s, lost_c = emu.frame_lost(0), emu.frame_lost(1)
        if not lost_s:
            q = codec.quantize("SENSOR_POS", {"Position": y.position_m, "Spool": y.spool_m})
            q.update(
                codec.quantize(
                    "SENSOR_AUX", {"LoadPressure": y.load_pressure_pa, "CoilCurrent": y.coil_current_a}
                )
            )
            sent.append(q)
            ks.append(k)
            u = codec.quantize("VALVE_CMD", {"CurrentSetpoint": law(q, idx)})["CurrentSetpoint"]
            idx += 1
            if not lost_c:
                hold.accept(u, True)
        delay.append(hold.tick())
        emu.advance(delay.popleft())
    return sent, ks


def _run(
    buses: tuple[can.BusABC, can.BusABC], sc: Scenario, law: Law, truth: bool = False
) -> tuple[EmulatorProcess, list[can.Message]]:
    emu_bus, client_bus = buses
    frames: list[can.Message] = []
    th = threading.Thread(target=_client, args=(client_bus, law, frames))
    th.start()
    proc = EmulatorProcess(
        PlantEmulation(load_params(), sc),
        FrameIO(emu_bus, FrameCodec(), OWN_FRAMES),
        EmulatorOptions(truth=truth, lockstep_timeout_s=5.0),
    )
    assert proc.run_lockstep(StopFlag(), N)
    th.join()
    return proc, frames


def _sensor_values(frames: list[can.Message]) -> list[dict[str, float]]:
    codec = FrameCodec()
    out: list[dict[str, float]] = []
    for m in frames:
        d = codec.classify(m)
        if d.name == "SENSOR_POS":
            assert d.values is not None, d
            out.append({k: d.values[k] for k in ("Position", "Spool")})
        elif d.name == "SENSOR_AUX":
            assert d.values is not None, d
            out[-1].update({k: d.values[k] for k in ("LoadPressure", "CoilCurrent")})
    return out


@pytest.mark.parametrize(
    "law,loss", [(recorded_law, 0.0), (p_law, 0.05)], ids=["recorded-current", "p-law-5pct-loss"]
)
def test_lockstep_equals_offline(buses: tuple[can.BusABC, can.BusABC], law: Law, loss: float) -> None:
    sc = _scenario(loss)
    proc, frames = _run(buses, sc, law)
    expected, ks = _offline(sc, law)
    got = _sensor_values(frames)
    assert len(got) == len(expected) == N - proc.lost_sensor
    for i, (g, e) in enumerate(zip(got, expected, strict=False)):
        assert g == e, f"sample k={ks[i]}: {g} != {e}"  # bit for bit after quantization
    assert proc.periods == N
    if loss:
        assert proc.lost_sensor > 0 and proc.lost_cmd > 0


def test_fault_onset_on_the_exact_sample(buses: tuple[can.BusABC, can.BusABC]) -> None:
    """PLANT_FAULTS for each event appears between sensor frames k−1 and k of its sample."""
    _, frames = _run(buses, _scenario(), recorded_law, truth=True)
    codec = FrameCodec()
    k = -1
    onsets: list[tuple[int, float, float]] = []
    last = (1.0, 1.0)
    for m in frames:
        d = codec.classify(m)
        if d.name == "SENSOR_POS":
            k += 1
        elif d.name == "PLANT_FAULTS":
            assert d.values is not None, d
            cur = (d.values["KLoe"], d.values["KDft"])
            if cur != last:
                onsets.append((k + 1, *cur))
            last = cur
    assert onsets == [(EVENT_K[0], 0.5, 1.0), (EVENT_K[1], 0.5, 0.8)]
