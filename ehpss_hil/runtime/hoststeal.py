"""The hypervisor's share of a run: the *steal* time of ``/proc/stat`` (CPU time the host gave
to another guest while this VM had work), over a run, as a share of the time the VM wanted a
CPU. Stolen time stalls the whole vCPU; no setting of this program removes it. Read around every
``ehpss-hil run`` (``run.json``, the realtime verdict) and ``bench loop``.
"""

from __future__ import annotations

from pathlib import Path


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
