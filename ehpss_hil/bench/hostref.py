"""The host's share of the loop figures: the controller's own work, without bus or peer.

``ehpss-hil bench loop`` times the whole cycle of a loop that sleeps between periods. On a
virtual machine (or any host whose idle CPU halts) the first instructions after a sleep run
from cold caches and a cold branch predictor, and the same Python code takes about twice as
long as back to back. This measures that directly, so a table that misses a target says whether
the software or the host is to blame: the ``mmac`` control step plus one VALVE_CMD encode (the
work of a cycle that every deployment has), on a recorded fault-free measurement sequence, once
per period with a ``select()`` sleep between (as in the daemon), and back to back.

And the hypervisor's share: the *steal* time of ``/proc/stat`` (CPU time the host gave to
someone else while this VM had work), over a run, as a share of the time the VM wanted a CPU.
"""

from __future__ import annotations

import math
import select
import time
from pathlib import Path
from typing import Any

from ..codec import FrameCodec
from ..control.base import Measurement
from ..control.registry import make_controller
from ..physics.params import load_params
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


def cpu_times(stat: str | None = None) -> tuple[int, ...] | None:
    """The aggregate ``cpu`` line of ``/proc/stat`` (or of ``stat``, its text) as ticks: user,
    nice, system, idle, iowait, irq, softirq, steal, …; None where there is none or no steal
    column (not Linux, or a kernel before 2.6.11)."""
    try:
        text = Path("/proc/stat").read_text() if stat is None else stat
    except OSError:
        return None
    for line in text.splitlines():
        parts = line.split()
        if parts and parts[0] == "cpu":
            try:
                ticks = tuple(int(x) for x in parts[1:])
            except ValueError:
                return None
            return ticks if len(ticks) >= 8 else None
    return None


def steal_fraction(before: tuple[int, ...] | None, after: tuple[int, ...] | None) -> float | None:
    """Steal ticks between two :func:`cpu_times` readings as a share of the time this VM wanted
    a CPU: steal / (busy + steal), busy being user, nice, system, irq and softirq (idle and
    iowait left out; guest time is already inside user/nice). None without both readings or
    without any busy time."""
    if before is None or after is None:
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = (
        a - b for a, b in zip(after[:8], before[:8], strict=True)
    )
    wanted = user + nice + system + irq + softirq + steal
    return steal / wanted if wanted > 0 else None
