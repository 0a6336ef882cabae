"""Real-time process options (docs/design.md §8): SCHED_FIFO, CPU affinity, mlockall, gc.freeze.

Each option is best effort: when the OS refuses (no CAP_SYS_NICE, no such CPU, RLIMIT_MEMLOCK…)
a clear warning is logged and returned, and the process runs on without it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import os
from collections.abc import Callable

from ..config import RtOptions

log = logging.getLogger(__name__)

MCL_CURRENT = 1
MCL_FUTURE = 2


def set_fifo_priority(priority: int) -> str | None:
    """SCHED_FIFO at ``priority`` (1..99) for this process; returns a warning or None."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return (
            f"SCHED_FIFO priority {priority} not permitted ({exc}); running with the default "
            "scheduler (needs root or CAP_SYS_NICE / an rtprio limit)"
        )
    return None


def set_cpu(cpu: int) -> str | None:
    """Pin this process — every thread it has now, and (inherited) every later one — to CPU
    ``cpu``; returns a warning or None.

    ``sched_setaffinity(0)`` pins the calling thread only. A thread left unpinned (the log
    writer, started before the RT options are applied) runs on the other process's CPU, where
    that process's SCHED_FIFO loop preempts it — while it holds this process's GIL, which this
    loop then waits for (at 2 kHz with both processes pinned, the emulator missed 5 % of its
    periods)."""
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        tids = [0]
    try:
        for tid in tids:
            try:
                os.sched_setaffinity(tid, {cpu})
            except ProcessLookupError:  # the thread ended meanwhile
                pass
    except (OSError, ValueError, AttributeError) as exc:
        return f"CPU affinity {cpu} not permitted ({exc}); running unpinned"
    return None


def lock_memory() -> str | None:
    """mlockall(MCL_CURRENT | MCL_FUTURE) via libc; returns a warning or None."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6", use_errno=True)
    except OSError as exc:
        return f"mlockall unavailable ({exc})"
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        err = ctypes.get_errno()
        return (
            f"mlockall not permitted ({os.strerror(err)}); memory may be paged "
            "(needs root or a higher RLIMIT_MEMLOCK)"
        )
    return None


PR_SET_TIMERSLACK = 29


def set_timer_slack(slack_ns: int = 1) -> str | None:
    """prctl(PR_SET_TIMERSLACK): the kernel may delay a normal task's sleep wake-ups by up to
    50 µs by default to batch timers; 1 ns makes ``time.sleep`` wake on time (SCHED_FIFO tasks
    have no slack anyway). Returns a warning or None."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        if libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(slack_ns), 0, 0, 0) != 0:
            return f"timer slack not set ({os.strerror(ctypes.get_errno())})"
    except (OSError, AttributeError) as exc:
        return f"timer slack not set ({exc})"
    return None


def apply_rt_options(opts: RtOptions) -> list[str]:
    """Apply timer slack, priority, affinity and memory locking from ``opts``; returns the
    warnings (also logged).

    Call :func:`freeze_gc` separately, after configuration, just before the loop starts.
    """
    warnings: list[str] = []
    steps: list[Callable[[], str | None]] = [set_timer_slack]
    if opts.cpu >= 0:
        steps.append(lambda: set_cpu(opts.cpu))
    if opts.priority > 0:
        steps.append(lambda: set_fifo_priority(opts.priority))
    if opts.lock_memory:
        steps.append(lock_memory)
    for step in steps:
        w = step()
        if w is not None:
            log.warning(w)
            warnings.append(w)
    return warnings


def freeze_gc(enabled: bool = True) -> None:
    """Collect once, then move every object to the permanent generation (``gc.freeze``), so the
    loop's cyclic GC passes only scan what the loop itself allocates."""
    if enabled:
        gc.collect()
        gc.freeze()
