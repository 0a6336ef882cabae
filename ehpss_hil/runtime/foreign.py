"""What the controller does about frames from a transmitter that should not be there.

A second transmitter (issue #16): the controller's own VALVE_CMD received from elsewhere (an ID
collision, :class:`~.frameio.FrameIO`), the emulator's SENSOR_AUX ``CommandConflict`` (it saw two
VALVE_CMD sequences and centred the valve: firmware_sim/commanders.py), or a second SENSOR_POS
stream. The last one is told from a lossy bus by its E2E verdicts: frame loss only ever gives
OK_SOME_LOST (and one WRONG_SEQUENCE after more than ``max_delta_counter`` lost in a row), while
a second sender interleaves its counter with the sensor's and half of all SENSOR_POS frames fail
the sequence check (REPEATED, WRONG_SEQUENCE); :data:`SENSOR_SEQ_LIMIT` of the last
:data:`SENSOR_SEQ_WINDOW` is a conflict (the reliability suite's peer that duplicates, delays and
reorders 22 % of its ticks reaches 34 at most). :class:`CollisionGuard` turns that evidence into
the loop's reaction (``watchdog.on_collision``): fail-safe with reason ID_COLLISION, left only
with ``auto_recover`` after ``recovery_cycles`` cycles without evidence, or a warning only.

:class:`SetpointGate`: SETPOINT overrides x_d only when enabled and within the configured limits.
"""

from __future__ import annotations

import logging
import math

from ..config import SetpointPolicy, Watchdog
from .collisions import IdCollisions

log = logging.getLogger("ehpss_hil.controller")

#: SENSOR_POS frames looked back over for a second transmitter, and the sequence failures
#: (REPEATED, WRONG_SEQUENCE) among them that make one
SENSOR_SEQ_WINDOW = 100
SENSOR_SEQ_LIMIT = 40
#: the VALVE_CMD frames (own ID) the controller sends
COMMAND_FRAME = "VALVE_CMD"
#: a rejected-SETPOINT warning: the first, then every this many
SETPOINT_WARN_EVERY = 1000


class SequenceWindow:
    """Sequence failures among the last ``window`` frames of one ID; :attr:`conflict` from
    ``limit`` of them until a whole window holds none (as firmware_sim/commanders.py)."""

    __slots__ = ("_bad", "_i", "_limit", "_ring", "conflict", "conflicts", "failures")

    def __init__(self, window: int = SENSOR_SEQ_WINDOW, limit: int = SENSOR_SEQ_LIMIT) -> None:
        self._ring = bytearray(window)
        self._i = 0
        self._bad = 0
        self._limit = limit
        self.conflict = False
        self.conflicts = 0  # conflicts declared
        self.failures = 0  # sequence failures counted

    def add(self, failed: bool) -> None:
        """One frame: ``failed`` when its E2E verdict was REPEATED or WRONG_SEQUENCE."""
        v = int(failed)
        self._bad += v - self._ring[self._i]
        self._ring[self._i] = v
        self._i = (self._i + 1) % len(self._ring)
        self.failures += v
        if not self.conflict and self._bad >= self._limit:
            self.conflict = True
            self.conflicts += 1
        elif self.conflict and self._bad == 0:
            self.conflict = False


class CollisionGuard:
    """Evidence of a second transmitter, per cycle, and the reaction policy."""

    def __init__(self, wd: Watchdog, collisions: IdCollisions) -> None:
        self.fault_on_collision = wd.on_collision == "fault"
        self._auto_recover = wd.auto_recover
        self._recovery_cycles = wd.recovery_cycles
        self._collisions = collisions
        self._cmd_seen = 0
        self.sensor = SequenceWindow()
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
        n_cmd = self._collisions.by_name.get(COMMAND_FRAME, 0)
        causes = [
            c
            for c, hit in (
                (f"{COMMAND_FRAME} from another transmitter", n_cmd > self._cmd_seen),
                ("the emulator reports CommandConflict", self._conflict_flag),
                ("a second SENSOR_POS transmitter", self.sensor.conflict),
            )
            if hit
        ]
        self._cmd_seen = n_cmd
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
            "valve_cmd_foreign": self._cmd_seen,
            "command_conflict_frames": self.conflict_frames,
            "sensor_pos_conflicts": self.sensor.conflicts,
            "sensor_pos_sequence_failures": self.sensor.failures,
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
