"""What the controller does about frames from a transmitter that should not be there.

A second transmitter: the controller's own VALVE_CMD received from elsewhere (an ID collision,
:class:`~.frameio.FrameIO`), another node's SYNC or NMT frame under
``protocol: cia408`` (one producer each), the emulator's SENSOR_AUX ``CommandConflict`` (it saw two VALVE_CMD
sequences and centred the valve: firmware_sim/commanders.py), or a second SENSOR_POS stream
(:class:`SensorStreams`). :class:`CollisionGuard` turns that evidence into the loop's reaction
(``watchdog.on_collision``): fail-safe with reason ID_COLLISION, left only with ``auto_recover``
after ``recovery_cycles`` cycles without evidence, or a warning only.

A second SENSOR_POS stream needs two kinds of evidence at once, because each alone has an
innocent cause on a single sensor:

- **sequence failures**: :data:`SENSOR_SEQ_LIMIT` of the last :data:`SENSOR_SEQ_WINDOW` frames
  REPEATED or WRONG_SEQUENCE. A second sender interleaves its own counter and fails half of all
  frames; but one sensor does the same when the bus or a starved receiver loses frames in bursts
  (a gap of more than ``max_delta_counter`` is a WRONG_SEQUENCE, and under load such gaps come
  one after the other), or when it duplicates and reorders.
- **more frames than one sensor sends**: a sensor samples on its own clock, one frame per control
  period, so in any :data:`~ehpss_hil.protocol.ratewindow.SENSOR_RATE_WINDOW_CYCLES` periods
  (skipped ones included) one sensor delivers at most that many distinct frames, plus what a late
  delivery shifts into the window (:class:`~ehpss_hil.protocol.ratewindow.RateWindow`). Copies
  of one of the last :data:`SENSOR_COPY_MEMORY` frames (byte-identical) are not new frames, and
  neither are frames received before the stale window (a starved receiver's backlog: sent over
  the periods it slept through) nor, on buses without receive timestamps, the frames drained
  right after skipped periods. Two senders deliver about twice the periods; a sensor running
  faster than the control rate does too, but has no sequence failures.
:class:`SetpointGate`: SETPOINT overrides x_d only when enabled and within the configured limits.
"""

from __future__ import annotations

import logging
import math
from collections import deque

from ..config import SetpointPolicy, Watchdog
from ..protocol.ratewindow import RateWindow
from .collisions import IdCollisions

log = logging.getLogger("ehpss_hil.controller")

#: SENSOR_POS frames looked back over for a second transmitter, and the sequence failures
#: (REPEATED, WRONG_SEQUENCE) among them that are evidence of one (half of all frames fail with
#: two senders; the reliability suite's peer that duplicates, delays and reorders 22 % of its
#: ticks reaches 34 of 100 on an idle host)
SENSOR_SEQ_WINDOW = 100
SENSOR_SEQ_LIMIT = 40
#: a frame byte-identical to one of this many previous SENSOR_POS frames is a copy (the counter
#: is 4 bits: a genuine frame repeats the bytes of one 16 frames back only at rest, noise-free)
SENSOR_COPY_MEMORY = 8
#: the own frames whose other transmitter is a second commander: VALVE_CMD (the valve's RPDO under
#: cia408), and the CANopen master's SYNC and NMT (one producer each on a CANopen network)
COMMAND_FRAMES = ("VALVE_CMD", "SYNC", "NMT")
#: a rejected-SETPOINT warning: the first, then every this many
SETPOINT_WARN_EVERY = 1000


class SequenceWindow:
    """Sequence failures among the last ``window`` frames of one ID (:attr:`evident` from
    ``limit`` of them, :attr:`quiet` when a whole window holds none)."""

    __slots__ = ("_bad", "_i", "_limit", "_ring", "failures")

    def __init__(self, window: int = SENSOR_SEQ_WINDOW, limit: int = SENSOR_SEQ_LIMIT) -> None:
        self._ring = bytearray(window)
        self._i = 0
        self._bad = 0
        self._limit = limit
        self.failures = 0  # sequence failures counted

    def add(self, failed: bool) -> None:
        """One frame: ``failed`` when its E2E verdict was REPEATED or WRONG_SEQUENCE."""
        v = int(failed)
        self._bad += v - self._ring[self._i]
        self._ring[self._i] = v
        self._i = (self._i + 1) % len(self._ring)
        self.failures += v

    @property
    def evident(self) -> bool:
        return self._bad >= self._limit

    @property
    def quiet(self) -> bool:
        return self._bad == 0


class SensorStreams:
    """A second SENSOR_POS transmitter, from the sequence and the rate evidence together (see
    the module docstring): :attr:`conflict` while both hold, until a whole sequence window
    holds no failure."""

    __slots__ = ("_recent", "conflict", "conflicts", "max_frames", "rate", "sequence")

    def __init__(self) -> None:
        self.sequence = SequenceWindow()
        self.rate = RateWindow()
        self._recent: deque[bytes] = deque(maxlen=SENSOR_COPY_MEMORY)
        self.conflict = False
        self.conflicts = 0  # conflicts declared
        #: the most distinct frames seen in one rate window (one sensor: about the window)
        self.max_frames = 0

    @property
    def failures(self) -> int:
        """Sequence failures counted."""
        return self.sequence.failures

    def add(self, failed: bool, data: bytes, cycle: int, countable: bool = True) -> None:
        """One SENSOR_POS frame drained in the loop's cycle ``cycle``: ``failed`` when its
        verdict was REPEATED or WRONG_SEQUENCE; ``countable`` False for a frame that belongs
        to an earlier period (stale, or a backlog after skipped periods)."""
        self.sequence.add(failed)
        if countable and data not in self._recent:
            self.rate.add(cycle)
            self.max_frames = max(self.max_frames, self.rate.total)
        self._recent.append(data)
        if not self.conflict and self.sequence.evident and self.rate.total > self.rate.bound():
            self.conflict = True
            self.conflicts += 1
        elif self.conflict and self.sequence.quiet:
            self.conflict = False


class CollisionGuard:
    """Evidence of a second transmitter, per cycle, and the reaction policy."""

    def __init__(self, wd: Watchdog, collisions: IdCollisions) -> None:
        self.fault_on_collision = wd.on_collision == "fault"
        self._auto_recover = wd.auto_recover
        self._recovery_cycles = wd.recovery_cycles
        self._collisions = collisions
        self._seen = dict.fromkeys(COMMAND_FRAMES, 0)
        self.sensor = SensorStreams()
        self._conflict_flag = False  # CommandConflict in a SENSOR_AUX of this cycle
        #: SENSOR_AUX frames with CommandConflict 1
        self.conflict_frames = 0
        #: episodes: evidence after ``recovery_cycles`` cycles without (or none before)
        self.episodes = 0
        self.quiet_cycles = 0
        self.evident = False
        #: the loop must stay in fail-safe (policy fault): latched, see the module docstring
        self.holding = False
        self.last_cause = ""

    def command_conflict(self, flag: bool) -> None:
        """A usable SENSOR_AUX's CommandConflict bit."""
        if flag:
            self._conflict_flag = True
            self.conflict_frames += 1

    def update(self, cycle: int) -> bool:
        """Account one cycle; True when the loop must be in fail-safe for ID_COLLISION now."""
        counts = {n: self._collisions.by_name.get(n, 0) for n in COMMAND_FRAMES}
        causes = [f"{n} from another transmitter" for n, k in counts.items() if k > self._seen[n]]
        causes += [
            c
            for c, hit in (
                ("the emulator reports CommandConflict", self._conflict_flag),
                ("a second SENSOR_POS transmitter", self.sensor.conflict),
            )
            if hit
        ]
        self._seen = counts
        self._conflict_flag = False
        if causes:
            if not self.evident:
                self.episodes += 1
                self.last_cause = "; ".join(causes)
                log.warning(
                    "cycle %d: second transmitter: %s (%s)",
                    cycle,
                    self.last_cause,
                    "fail-safe ID_COLLISION"
                    if self.fault_on_collision
                    else "on_collision: warn, control goes on",
                )
            self.evident = True
            self.quiet_cycles = 0
            self.holding = self.holding or self.fault_on_collision
        else:
            self.quiet_cycles += 1
            if self.quiet_cycles >= self._recovery_cycles:  # the episode is over
                self.evident = False
                self.holding = self.holding and not self._auto_recover
        return self.holding

    def summary(self) -> dict[str, object]:
        """Counters (JSON-able)."""
        return {
            "policy": "fault" if self.fault_on_collision else "warn",
            "episodes": self.episodes,
            "valve_cmd_foreign": self._seen["VALVE_CMD"],
            "sync_foreign": self._seen["SYNC"],
            "nmt_foreign": self._seen["NMT"],
            "command_conflict_frames": self.conflict_frames,
            "sensor_pos_conflicts": self.sensor.conflicts,
            "sensor_pos_sequence_failures": self.sensor.failures,
            "sensor_pos_max_frames_per_window": self.sensor.max_frames,
            "last_cause": self.last_cause,
        }


class SetpointGate:
    """SETPOINT (Override, Position) → the x_d override, or rejected (counted)."""

    def __init__(self, policy: SetpointPolicy) -> None:
        self.policy = policy
        self.accepted = 0
        self.rejected = 0

    def admit(self, override: bool, position_m: float, x_d_m: float) -> bool:
        """True when a SETPOINT may take effect: enabled, and an override within ``max_abs_m``
        of 0 and ``max_step_m`` of the x_d in force (``x_d_m``); Override 0 (back to the
        configured trajectory) needs only ``enabled``."""
        p = self.policy
        ok = p.enabled and (
            not override
            or (
                math.isfinite(position_m)
                and abs(position_m) <= p.max_abs_m
                and abs(position_m - x_d_m) <= p.max_step_m
            )
        )
        if ok:
            self.accepted += 1
            return True
        self.rejected += 1
        if self.rejected % SETPOINT_WARN_EVERY == 1:
            why = (
                "setpoint.enabled is false"
                if not p.enabled
                else f"{position_m:.6g} m is beyond ±{p.max_abs_m:g} m or more than "
                f"{p.max_step_m:g} m from x_d {x_d_m:.6g} m"
            )
            log.warning("SETPOINT rejected (%s); %d rejected so far", why, self.rejected)
        return False
