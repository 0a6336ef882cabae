"""A bench-like candump log without a bus: the lockstep loop with real frames, every frame logged.

Per sample k (timestamps ``t0 + k·Ts`` plus a few µs per frame, s): PLANT_TRUTH (when ``truth``),
SENSOR_POS + SENSOR_AUX (unless the scenario's seeded loss drops them), the controller's
VALVE_CMD (``CycleCount = k``, unless dropped), every ``status_every`` cycles CTRL_STATUS and one
CTRL_INDEX per model slot, PLANT_FAULTS on change and at 10 Hz. The plant applies the command
``transport_delay_samples`` later, as in :mod:`ehpss_hil.sim.lockstep` (whose frames transport
this reproduces). Used by the report/replay tests and to try ``ehpss-hil report`` offline.
"""

from __future__ import annotations

import os
from collections import deque
from pathlib import Path

from ..canlog import CandumpLogger
from ..canlog.sidecar import jsonable
from ..codec import FrameCodec
from ..control.controllers import LoopBase
from ..control.registry import make_controller
from ..control.tuning import ControlTuning
from ..driver import ControllerDriver
from ..emulation import PlantEmulation, SensorSample
from ..physics.load import load_params
from ..physics.params import Params
from ..runtime.status_frames import MODE_CODE, MODE_UNKNOWN
from ..scenario import Scenario

_T0_S = 1_767_225_600.0  # 2026-01-01T00:00:00Z: a fixed wall-clock origin (reproducible logs)


class _Bench:
    """Emulator side + controller side + logger for one run."""

    def __init__(
        self,
        sc: Scenario,
        ctrl: LoopBase,
        prm: Params,
        log: CandumpLogger,
        truth: bool,
        t0_s: float,
        x_d: list[float],
    ) -> None:
        self.sc, self.ctrl, self.log, self.truth, self.t0 = sc, ctrl, log, truth, t0_s
        self.emu = PlantEmulation(prm, sc)
        self.tx_emu, self.tx_ctrl, self.rx_ctrl = FrameCodec(), FrameCodec(), FrameCodec()
        self.drv = ControllerDriver(ctrl, x_d.__getitem__)
        self.faults = self.emu.faults

    def send(self, codec: FrameCodec, name: str, values: dict[str, float], t_s: float) -> None:
        self.log.log(codec.encode(name, values, timestamp_s=t_s))

    def sensors(self, s: SensorSample, t: float) -> None:
        """Truth and sensor frames of sample k; the controller decodes the sensor frames."""
        if self.truth:
            self.send(
                self.tx_emu,
                "PLANT_TRUTH",
                {
                    "Position": _clip(s.true_position_m, 0.5),
                    "SpoolActual": _clip(s.true_spool_m, 0.01),
                    "Stuck": int(s.faults.stuck),
                },
                t,
            )
        if self.emu.frame_lost(0):  # lost on the way: the sensor's E2E counters move on
            self.tx_emu.skip("SENSOR_POS")
            self.tx_emu.skip("SENSOR_AUX")
            return
        f1 = self.tx_emu.encode(
            "SENSOR_POS", {"Position": _clip(s.position_m, 0.5), "Spool": _clip(s.spool_m, 0.01)}, t + 10e-6
        )
        f2 = self.tx_emu.encode(
            "SENSOR_AUX",
            {
                "LoadPressure": _clip(s.load_pressure_pa, 4e7),
                "CoilCurrent": _clip(s.coil_current_a, 1),
                "ValveEnabled": 1,
                "CurrentSaturated": int(s.current_saturated),
            },
            t + 20e-6,
        )
        self.log.log(f1)
        self.log.log(f2)
        d1, d2 = self.rx_ctrl.classify(f1), self.rx_ctrl.classify(f2)
        if d1.values and d2.values:
            self.drv.take(d1)
            self.drv.take(d2)

    def status(self, t: float) -> None:
        st = self.ctrl.status()
        self.send(
            self.tx_ctrl,
            "CTRL_STATUS",
            {
                "State": 2,
                "Mode": MODE_CODE.get(self.ctrl.mode, MODE_UNKNOWN),
                "NominalFallback": int(st.fallback),
                "ActiveSpoolModel": st.active_model.get("spool", -1) & 0xF,
                "ActivePosModel": st.active_model.get("position", -1) & 0xF,
                "KLoeHat": _clip(st.k_loe_hat, 4.095, 0.0),
                "KDftHat": _clip(st.k_dft_hat, 4.095, 0.0),
                "Switches": min(st.switches, 255),
            },
            t,
        )
        for slot, j in sorted(st.index.items()):
            if 0 <= slot <= 15:
                self.send(
                    self.tx_ctrl,
                    "CTRL_INDEX",
                    {
                        "ModelSlot": slot,
                        f"J_{slot}": _clip(j, 3e38),
                        f"Theta_{slot}": _clip(st.theta.get(slot, 0.0), 6.5535, 0.0),
                    },
                    t,
                )

    def plant_faults(self, k: int, t: float) -> None:
        f = self.emu.faults
        if self.truth and (f != self.faults or k % 100 == 0):
            self.send(
                self.tx_emu,
                "PLANT_FAULTS",
                {"KLoe": min(f.k_loe, 6.5535), "KQ": min(f.k_q, 6.5535), "KDft": min(f.k_dft, 6.5535)},
                t,
            )
        self.faults = f


def _clip(v: float, hi: float, lo: float | None = None) -> float:
    lo = -hi if lo is None else lo
    return lo if v < lo else hi if v > hi else v


def write_lockstep_log(
    scenario: Scenario,
    mode: str,
    path: str | os.PathLike[str],
    params: Params | None = None,
    tuning: ControlTuning | None = None,
    truth: bool = True,
    status_every: int = 20,
    t0_s: float = _T0_S,
    queue_lines: int = 200_000,
) -> Path:
    """Run ``scenario`` with controller ``mode`` and log every frame to ``path``; returns it.
    ``queue_lines``: the logger's queue (the loop outruns its writer thread: a run of more than
    about 40 000 samples needs a longer one, else frames are dropped and counted)."""
    prm = params if params is not None else load_params()
    ts = scenario.sample_time_s
    ctrl = make_controller(mode, prm, ts, tuning, scenario.reference)
    side = {
        "tool": "ehpss_hil.sim.samplelog (lockstep, no bus)",
        "scenario": jsonable(scenario),
        "config": {"mode": mode, "rate_hz": 1.0 / ts},
        "clock": "synthetic: t0 + k*Ts (+ µs per frame), s since the Unix epoch",
    }
    log = CandumpLogger(path, iface="vcan0", sidecar=side, queue_lines=queue_lines)
    x_d = scenario.reference_samples().tolist()
    b = _Bench(scenario, ctrl, prm, log, truth, t0_s, x_d)
    set_truth = getattr(ctrl, "set_truth", None)
    queue: deque[float | None] = deque([0.0] * scenario.transport_delay_samples)
    held = 0.0
    try:
        for k in range(len(x_d)):
            t = t0_s + k * ts
            s = b.emu.measure()
            b.sensors(s, t)
            if set_truth is not None:
                set_truth(s.faults)
            fresh, echo = b.drv.fresh, b.drv.counter
            cur, enable = b.drv.step()
            current = cur if enable else 0.0
            f = b.tx_ctrl.encode(
                "VALVE_CMD",
                {
                    "CurrentSetpoint": current,
                    "Enable": 1,
                    "SensorCounterEcho": echo if fresh else 0,
                    "CycleCount": k & 0xFFFF,
                },
                t + 100e-6,
            )
            lost = b.emu.frame_lost(1)
            if not lost:
                log.log(f)
            queue.append(
                None
                if lost
                else b.tx_ctrl.quantize("VALVE_CMD", {"CurrentSetpoint": current})["CurrentSetpoint"]
            )
            arrived = queue.popleft()
            held = held if arrived is None else arrived
            b.emu.advance(held)
            if (k + 1) % status_every == 0:
                b.status(t + 150e-6)
            b.plant_faults(k, t + 200e-6)
    finally:
        log.close()
    return Path(path)
