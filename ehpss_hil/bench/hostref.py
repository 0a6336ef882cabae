"""The host's share of the loop figures: the controller's own work, without bus or peer.

``ehpss-hil bench loop`` times the whole cycle of a loop that sleeps between periods. On a
virtual machine (or any host whose idle CPU halts) the first instructions after a sleep run
from cold caches and a cold branch predictor, and the same Python code takes about twice as
long as back to back. This measures that directly, so a table that misses a target says whether
the software or the host is to blame: the ``mmac`` control step plus one VALVE_CMD encode (the
work of a cycle that every deployment has), on a recorded fault-free measurement sequence, once
per period with a ``select()`` sleep between (as in the daemon), and back to back.

The hypervisor's share (steal time over a run) is :mod:`ehpss_hil.runtime.hoststeal`.
"""

from __future__ import annotations

import math
import select
import time
from typing import Any

from ..codec import FrameCodec
from ..control.base import Measurement
from ..control.registry import make_controller
from ..physics.load import load_params
from ..runtime.stats import Ring
from ..scenario import Reference


def measure(rate_hz: float, periods: int = 3000) -> dict[str, Any]:
    """Time the control step + encode ``periods`` times after a sleep of one period and as many
    times back to back; returns {"after_sleep_s": percentiles, "back_to_back_s": percentiles}."""
    ts = 1.0 / rate_hz
    ref = Reference(kind="sine", amplitude_m=1e-3, omega_rad_s=5.0)
    ctrl = make_controller("mmac", load_params(), ts, reference=ref)
    codec = FrameCodec()
    meas = Measurement()
    perf = time.perf_counter

    def work(k: int) -> float:
        x = 1e-3 * math.sin(5.0 * k * ts)
        meas.position_m, meas.spool_m, meas.reference_m = x, 5e-6 * math.cos(5.0 * k * ts), x
        meas.samples = 1 if k else 0
        t0 = perf()
        cmd = ctrl.step(meas)
        codec.encode(
            "VALVE_CMD",
            {
                "CurrentSetpoint": max(-1.0, min(1.0, cmd.current_a)),
                "Enable": 1,
                "SensorCounterEcho": k & 0x0F,
                "CycleCount": k & 0xFFFF,
            },
        )
        return perf() - t0

    for k in range(500):  # past the controller's warm-up
        work(k)
    slept, hot = Ring(periods), Ring(periods)
    for k in range(500, 500 + periods):
        select.select([], [], [], ts)
        slept.add(work(k))
    for k in range(500 + periods, 500 + 2 * periods):
        hot.add(work(k))
    return {"after_sleep_s": slept.summary(), "back_to_back_s": hot.summary()}
