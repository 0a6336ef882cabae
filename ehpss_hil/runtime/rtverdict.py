"""Whether a realtime run's figures are the controller's: did the host hold the rate?

A realtime run (``ehpss-hil run``, ``demo``, ``bench loop``) scores like the offline simulation
only when both processes ran on their grid: every period executed on time, the valve never
handed the fail-safe command because the loop itself starved. :func:`judge` reads the counters
both processes already write at exit (``controller-summary.json``, ``emulator-summary.json``)
and the host's steal time over the run (when measured), compares them with
:class:`RealtimeThresholds` and returns a :class:`RealtimeVerdict`: valid or not, with one
reason per threshold crossed. A lockstep run is always valid: its plant advances one period per
command, so timing does not reach the figures.

Pure: no I/O, no project imports. The thresholds are documented in docs/runtime.md
("Is a realtime figure valid?").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

#: exit code of ``ehpss-hil run``/``demo`` when every process ended cleanly and the files are
#: written but the realtime figures are not valid (2: bad input, 3: missing interface)
REALTIME_INVALID_EXIT = 4

LOCKSTEP_REASON = "lockstep: timing does not affect the figures"
#: what to do about a run that is not valid (printed after the reasons)
ADVICE = (
    "these figures are not the controller's: rerun with --lockstep (deterministic), with RT "
    "options (rt.priority and rt.cpu in the controller and emulator configs) or on a quieter host"
)
#: watchdog reasons a starved process causes (the controller's own loop, or sensor frames that
#: came late or with counters jumped over skipped periods); the others come from the data
TIMING_TRIP_REASONS = ("SENSOR_TIMEOUT", "E2E_ERRORS")


def _origin(unit: str, why: str) -> dict[str, str]:
    return {"unit": unit, "origin": why}


@dataclass(frozen=True)
class RealtimeThresholds:
    """The most a realtime run may show and still count as valid (each field: unit, origin)."""

    #: LOOP_OVERRUN fail-safes of the controller (count)
    overrun_failsafes: int = field(
        default=0,
        metadata=_origin(
            "count",
            "each one hands the valve 0 A for at least watchdog.recovery_cycles periods: a "
            "command no offline figure contains",
        ),
    )
    #: sensor-timeout / E2E trips in a scenario that loses no frame, the one at the end of the
    #: run (the emulator stopping first) not counted (count)
    sensor_trips: int = field(
        default=0,
        metadata=_origin(
            "count",
            "without scenario frame loss only a starved emulator or controller makes sensor "
            "frames late or jump; each trip is a fail-safe interval",
        ),
    )
    #: skipped periods of either process, as a share of its periods (1)
    skipped_fraction: float = field(
        default=1e-3,
        metadata=_origin(
            "1",
            "10 × the RT overrun target at 1 kHz (docs/design.md §11, 1e-4); each skipped "
            "period is a sample neither process handled on time (stepped blind, counted lost)",
        ),
    )
    #: wake-up lateness p99 of either process (periods)
    lateness_p99_periods: float = field(
        default=0.5,
        metadata=_origin(
            "periods",
            "half a period late plus the 300 µs phase lock and ~100 µs compute, the command "
            "misses the emulator's next period: one more period of transport delay than the "
            "offline simulation has",
        ),
    )
    #: the host's steal time over the run, share of the time this VM wanted a CPU (1)
    steal_fraction: float = field(
        default=0.05,
        metadata=_origin(
            "1",
            "the hypervisor stalls the whole vCPU; at 2–3 % steal this VM's lateness p99 was "
            "already > 400 µs (docs/runtime.md, 'The host's share')",
        ),
    )


@dataclass(frozen=True)
class RealtimeVerdict:
    """Valid or not, and why (one reason per threshold crossed; the lockstep note when valid
    by construction)."""

    valid: bool
    reasons: list[str]

    def line(self) -> str:
        """The verdict as the first line of a run's output."""
        if self.valid:
            why = f" ({'; '.join(self.reasons)})" if self.reasons else ""
            return f"realtime: valid{why}"
        return f"realtime: NOT VALID — {'; '.join(self.reasons)}; {ADVICE}"

    def to_json(self) -> dict[str, Any]:
        """``realtime_valid`` and ``realtime_reasons``, the keys of ``metrics.json``."""
        return {"realtime_valid": self.valid, "realtime_reasons": list(self.reasons)}


def combine(by_run: Mapping[str, RealtimeVerdict]) -> RealtimeVerdict:
    """One verdict over several runs (e.g. the demo's nrc and mmac): valid when each is; the
    reasons of the runs that are not valid, each prefixed by the run's name."""
    valid = all(v.valid for v in by_run.values())
    reasons = [r if v.valid else f"{name}: {r}" for name, v in by_run.items() for r in v.reasons]
    return RealtimeVerdict(valid, list(dict.fromkeys(reasons)))


def end_trip(controller: Mapping[str, Any]) -> int:
    """1 when the controller's last watchdog trip is the silence after the emulator ended the
    run (a sensor timeout with no sensor frame after it), else 0."""
    return int(bool(controller.get("watchdog_trip_at_end")))


def _p99(summary: Mapping[str, Any] | None, key: str = "lateness_s") -> float | None:
    v = ((summary or {}).get("stats") or {}).get(key, {}).get("p99")
    return float(v) if isinstance(v, int | float) and v == v else None


def _skips(
    who: str, summary: Mapping[str, Any] | None, periods_key: str, th: RealtimeThresholds
) -> list[str]:
    if not summary:
        return []
    skipped = int(summary.get("skipped_periods", 0))
    limit = th.skipped_fraction * max(int(summary.get(periods_key, 0)), 1)
    if skipped > limit:
        return [
            f"{who} skipped {skipped} periods (limit {limit:.0f}, {th.skipped_fraction:g} of its periods)"
        ]
    return []


def _late(who: str, summary: Mapping[str, Any] | None, period_s: float, th: RealtimeThresholds) -> list[str]:
    p99 = _p99(summary)
    limit = th.lateness_p99_periods * period_s
    if p99 is not None and p99 > limit:
        return [f"{who} woke up late: p99 {p99 * 1e6:.0f} µs (limit {limit * 1e6:.0f} µs)"]
    return []


def _trips(controller: Mapping[str, Any], frame_loss: bool, th: RealtimeThresholds) -> list[str]:
    out = []
    by = controller.get("watchdog_trips_by_reason") or {}
    overrun = int(by.get("LOOP_OVERRUN", controller.get("overrun_trips", 0)))
    if overrun > th.overrun_failsafes:
        out.append(f"controller LOOP_OVERRUN fail-safe {overrun}× (limit {th.overrun_failsafes})")
    if not frame_loss:
        sensor = sum(int(by.get(r, 0)) for r in TIMING_TRIP_REASONS) - end_trip(controller)
        if sensor > th.sensor_trips:
            names = "/".join(r for r in TIMING_TRIP_REASONS if by.get(r))
            out.append(
                f"controller watchdog tripped {sensor}× on late sensor frames ({names}; the "
                f"scenario loses none; limit {th.sensor_trips})"
            )
    return out


def judge(
    controller: Mapping[str, Any],
    emulator: Mapping[str, Any] | None,
    period_s: float,
    *,
    lockstep: bool = False,
    frame_loss: bool = False,
    steal_fraction: float | None = None,
    thresholds: RealtimeThresholds | None = None,
) -> RealtimeVerdict:
    """The verdict on one run from its processes' exit summaries.

    ``controller``/``emulator``: the ``--summary-json`` dicts (the emulator's may be missing);
    ``period_s``: the loop period (s); ``frame_loss``: the scenario loses frames on purpose (its
    watchdog trips are then the scenario's, as offline); ``steal_fraction``: the host's steal
    time over the run (None: not measured)."""
    if lockstep:
        return RealtimeVerdict(True, [LOCKSTEP_REASON])
    th = thresholds or RealtimeThresholds()
    reasons = [
        *_trips(controller, frame_loss, th),
        *_skips("controller", controller, "cycles", th),
        *_skips("emulator", emulator, "periods", th),
        *_late("controller", controller, period_s, th),
        *_late("emulator", emulator, period_s, th),
    ]
    if steal_fraction is not None and steal_fraction > th.steal_fraction:
        reasons.append(f"host steal time {100 * steal_fraction:.1f} % (limit {100 * th.steal_fraction:g} %)")
    return RealtimeVerdict(not reasons, reasons)
