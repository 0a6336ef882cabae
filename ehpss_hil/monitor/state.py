"""What the bus says, folded for the monitor: latest values, counters, rates and a decimated
series of rows. Pure: :meth:`MonitorState.feed` takes classified frames, :meth:`MonitorState.
snapshot` gives JSON-ready dicts; no I/O, no clock of its own (times come with the frames).

Rows (:data:`ROW_FIELDS`) are taken at most every ``row_period_s`` of receive time, each holding
the newest value of every signal (zero-order hold), so a 1 kHz bus gives 100 rows/s at the
default 10 ms whatever the frame rate; a page that draws them is independent of the bus load.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from ..codec import Decoded, FrameCodec, Verdict
from .reference import ReferenceTrack

#: the columns of a row; SI units (s, m, A, gains dimensionless)
ROW_FIELDS = (
    "t_s",  # receive time, s since the Unix epoch
    "x_true_m",  # PLANT_TRUTH.Position
    "y_s_m",  # SENSOR_POS.Position (the sensor: k_DFT·x)
    "x_d_m",  # desired position at the controller's sample index (needs its reference)
    "y_m_m",  # reference-model output (needs its reference)
    "e_m",  # tracking error x_true − y_m (y_s − y_m without PLANT_TRUTH)
    "i_cmd_a",  # VALVE_CMD.CurrentSetpoint
    "i_applied_a",  # SENSOR_AUX.CoilCurrent
    "k_loe_hat",
    "k_dft_hat",
    "k_loe_true",  # PLANT_FAULTS (bench only)
    "k_dft_true",
    "k_q_true",
    "stuck",  # PLANT_TRUTH.Stuck: 1 while the position sensor is stuck (bench only)
    "state",  # CTRL_STATUS.State code (3: FAULT); the page shades the fail-safe from it
    "failsafe_reason",  # CTRL_STATUS.FailsafeReason code
    "fallback",  # CTRL_STATUS.NominalFallback (1: loop held on nominal compensation)
    "fallback_reason",  # CTRL_STATS.FallbackReason code
)
#: CTRL_STATUS State code of the fail-safe (the DBC's value table names it FAULT; a test checks)
STATE_FAULT = 3
#: FAULT_INJECT_ACK answers kept for the page (newest last)
ACKS_KEPT = 20
#: default time between two rows (s)
ROW_PERIOD_S = 0.01
#: rows kept for a page that connects late (60 s at the default period)
WINDOW_ROWS = 6000
#: the window of the rates (frames/s, rejected/s, bus load), s
RATE_WINDOW_S = 1.0
#: CTRL_INDEX slots not heard for this long are dropped from the J table (s)
INDEX_STALE_S = 2.0
#: no frame for this long puts a "bus silent" banner up (s)
SILENT_S = 1.0
#: CTRL_STATUS nibble of "no model bank"
NO_MODEL = 15
#: bits of a classic CAN data frame with an 11-bit ID and ``n`` data bytes, without stuffing:
#: SOF 1, ID 11, RTR 1, IDE 1, r0 1, DLC 4, data 8n, CRC 15, delimiter 1, ACK 2, EOF 7, IFS 3
FRAME_OVERHEAD_BITS = 47

#: signals whose DBC value tables name their values (CTRL_STATUS, CTRL_STATS, heartbeats, …)
_CHOICE_SIGNALS = (
    ("CTRL_STATUS", "State"),
    ("CTRL_STATUS", "FailsafeReason"),
    ("CTRL_STATUS", "Mode"),
    ("CTRL_STATS", "FallbackReason"),
    ("HEARTBEAT_CTRL", "NmtState"),
    ("FAULT_INJECT", "FaultKind"),
    ("FAULT_INJECT_ACK", "Status"),
)


def choice_names(codec: FrameCodec) -> dict[str, dict[int, str]]:
    """``{signal: {value: name}}`` from the DBC's value tables (``VAL_``)."""
    out: dict[str, dict[int, str]] = {}
    for frame, sig in _CHOICE_SIGNALS:
        if frame not in codec.names:  # an older DBC (no FAULT_INJECT_ACK): codes shown as numbers
            out[sig] = {}
            continue
        choices: dict[int, Any] = codec.message(frame).get_signal_by_name(sig).choices or {}
        out[sig] = {int(k): str(v) for k, v in choices.items()}
    return out


def _name(table: dict[int, str], value: Any) -> str:
    return table.get(int(value), str(int(value)))


def _json_float(v: float) -> float | None:
    return v if math.isfinite(v) else None


@dataclass
class _Rates:
    """Counts at the start of the current rate window and the last window's rates."""

    t0_s: float = math.nan
    frames0: int = 0
    bits0: int = 0
    rejected0: int = 0
    frames_per_s: float = 0.0
    bits_per_s: float = 0.0
    rejected_per_s: float = 0.0


@dataclass
class _Latest:
    """Newest value of each displayed signal (NaN: not heard yet)."""

    values: dict[str, float] = field(default_factory=lambda: dict.fromkeys(ROW_FIELDS, math.nan))
    status: dict[str, Any] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    faults: dict[str, Any] = field(default_factory=dict)
    aux_flags: dict[str, bool] = field(default_factory=dict)
    nmt: dict[str, str] = field(default_factory=dict)
    index: dict[int, tuple[float, float, float]] = field(default_factory=dict)  # slot → (J, θ, t)
    stuck: bool | None = None


class MonitorState:
    """The monitor's view of one bus.

    ``reference``: x_d/y_m at the controller's sample index (None: not shown); ``bitrate``: the
    bus's nominal bit rate (bit/s) for the load figure; ``row_period_s``: time between rows (s).
    """

    def __init__(
        self,
        choices: dict[str, dict[int, str]],
        reference: ReferenceTrack | None = None,
        bitrate: int = 1_000_000,
        row_period_s: float = ROW_PERIOD_S,
    ) -> None:
        self.choices = choices
        self.reference = reference
        self.bitrate = bitrate
        self.row_period_s = row_period_s
        self.rows: deque[tuple[int, tuple[float, ...]]] = deque(maxlen=WINDOW_ROWS)
        self.seq = 0
        self.verdicts: dict[str, int] = {v.name: 0 for v in Verdict}
        self.frames = 0
        self.bits = 0
        self.rejected = 0
        self.injects_seen = 0
        #: the emulator's answers to FAULT_INJECT (FAULT_INJECT_ACK), newest last
        self.acks: deque[dict[str, Any]] = deque(maxlen=ACKS_KEPT)
        self.acks_seen = 0
        #: entries into the fail-safe (CTRL_STATUS State → FAULT) heard
        self.failsafe_trips = 0
        self.first_t_s = math.nan
        #: receive time (s, epoch) of the controller's first ACTIVE cycle heard (run time 0)
        self.start_t_s = math.nan
        self.last_t_s = math.nan
        self._next_row_t = -math.inf
        self._latest = _Latest()
        self._rates = _Rates()
        self._cycle_raw: int | None = None
        self._cycle = 0  # unwrapped CycleCount
        self._cycle0: int | None = None  # CycleCount at the first Enable = 1
        self._saw_disabled = False  # a VALVE_CMD with Enable = 0 came before any with 1

    # ---- input ---------------------------------------------------------------------------------
    def feed(self, d: Decoded, dlc: int, t_s: float) -> None:
        """One classified frame of ``dlc`` data bytes received at ``t_s`` (s)."""
        self.frames += 1
        self.bits += FRAME_OVERHEAD_BITS + 8 * dlc
        self.verdicts[d.verdict.name] += 1
        if not d.verdict.usable:
            self.rejected += 1
        self.last_t_s = t_s
        if math.isnan(self.first_t_s):
            self.first_t_s = t_s
        if d.values is not None and d.name is not None:
            handler = _HANDLERS.get(d.name)
            if handler is not None:
                handler(self, d.values, t_s)
        self._roll_rates(t_s)
        if t_s >= self._next_row_t:
            self._take_row(t_s)

    def _take_row(self, t_s: float) -> None:
        v = self._latest.values
        v["t_s"] = t_s
        v["e_m"] = tracking_error(v)
        self.seq += 1
        self.rows.append((self.seq, tuple(v[f] for f in ROW_FIELDS)))
        self._next_row_t = (t_s if math.isinf(self._next_row_t) else self._next_row_t) + self.row_period_s
        if self._next_row_t <= t_s:  # a gap: restart the grid instead of bursting rows
            self._next_row_t = t_s + self.row_period_s

    def _roll_rates(self, t_s: float) -> None:
        r = self._rates
        if math.isnan(r.t0_s):
            r.t0_s = t_s
            return
        dt = t_s - r.t0_s
        if dt < RATE_WINDOW_S:
            return
        r.frames_per_s = (self.frames - r.frames0) / dt
        r.bits_per_s = (self.bits - r.bits0) / dt
        r.rejected_per_s = (self.rejected - r.rejected0) / dt
        r.t0_s, r.frames0, r.bits0, r.rejected0 = t_s, self.frames, self.bits, self.rejected

    # ---- per frame -----------------------------------------------------------------------------
    def _sensor_pos(self, v: dict[str, Any], t_s: float) -> None:
        self._latest.values["y_s_m"] = float(v["Position"])

    def _sensor_aux(self, v: dict[str, Any], t_s: float) -> None:
        self._latest.values["i_applied_a"] = float(v["CoilCurrent"])
        self._latest.aux_flags = {  # a vendor or CiA 408 valve reports none of them (False)
            k: bool(v.get(k, 0))
            for k in ("ValveEnabled", "CmdTimeout", "CurrentSaturated", "CommandConflict")
        }

    def _valve_cmd(self, v: dict[str, Any], t_s: float) -> None:
        lat = self._latest.values
        lat["i_cmd_a"] = float(v["CurrentSetpoint"])
        # a vendor or CiA 408 command carries no cycle count: each command is one cycle
        raw = int(v.get("CycleCount", ((self._cycle_raw or 0) + 1) % 65536))
        if self._cycle_raw is not None:
            self._cycle += (raw - self._cycle_raw) % 65536
        self._cycle_raw = raw
        if not v.get("Enable", 1):
            self._saw_disabled = True
        elif self._cycle0 is None and self._saw_disabled:
            # the controller's first ACTIVE cycle, seen: its reference starts here (k = 0). A
            # monitor that attached to an already ACTIVE controller never knows k and shows no
            # x_d rather than a shifted one
            self._cycle0 = self._cycle
            self.start_t_s = t_s
        if self.reference is not None and self._cycle0 is not None:
            lat["x_d_m"], lat["y_m_m"] = self.reference.at(self._cycle - self._cycle0)

    def _ctrl_status(self, v: dict[str, Any], t_s: float) -> None:
        lat = self._latest
        lat.values["k_loe_hat"] = float(v["KLoeHat"])
        lat.values["k_dft_hat"] = float(v["KDftHat"])
        if int(v["State"]) == STATE_FAULT and lat.values["state"] != STATE_FAULT:
            self.failsafe_trips += 1
        lat.values["state"] = float(v["State"])
        lat.values["failsafe_reason"] = float(v["FailsafeReason"])
        lat.values["fallback"] = float(v["NominalFallback"])
        c = self.choices
        lat.status = {
            "state": _name(c["State"], v["State"]),
            "failsafe_reason": _name(c["FailsafeReason"], v["FailsafeReason"]),
            "mode": _name(c["Mode"], v["Mode"]),
            "fallback": bool(v["NominalFallback"]),
            "active_spool": None if int(v["ActiveSpoolModel"]) == NO_MODEL else int(v["ActiveSpoolModel"]),
            "active_position": None if int(v["ActivePosModel"]) == NO_MODEL else int(v["ActivePosModel"]),
            "switches": int(v["Switches"]),
        }

    def _ctrl_index(self, v: dict[str, Any], t_s: float) -> None:
        slot = int(v["ModelSlot"])
        self._latest.index[slot] = (float(v[f"J_{slot}"]), float(v[f"Theta_{slot}"]), t_s)

    def _ctrl_stats(self, v: dict[str, Any], t_s: float) -> None:
        self._latest.values["fallback_reason"] = float(v["FallbackReason"])
        self._latest.stats = {
            "fallback_reason": _name(self.choices["FallbackReason"], v["FallbackReason"]),
            "overruns": int(v["Overruns"]),
            "ctrl_rejected": int(v["RejectedFrames"]),
            "cycle_time_max_s": float(v["CycleTimeMax"]),
        }

    def _plant_truth(self, v: dict[str, Any], t_s: float) -> None:
        self._latest.values["x_true_m"] = float(v["Position"])
        self._latest.values["stuck"] = float(v["Stuck"])
        self._latest.stuck = bool(v["Stuck"])

    def _plant_faults(self, v: dict[str, Any], t_s: float) -> None:
        lat = self._latest
        lat.values["k_loe_true"] = float(v["KLoe"])
        lat.values["k_dft_true"] = float(v["KDft"])
        lat.values["k_q_true"] = float(v["KQ"])
        lat.faults = {"k_q": float(v["KQ"])}

    def _heartbeat_ctrl(self, v: dict[str, Any], t_s: float) -> None:
        self._latest.nmt["controller"] = _name(self.choices["NmtState"], v["NmtState"])

    def _heartbeat_emu(self, v: dict[str, Any], t_s: float) -> None:
        self._latest.nmt["emulator"] = _name(self.choices["NmtState"], v["NmtState"])

    def _fault_inject(self, v: dict[str, Any], t_s: float) -> None:
        self.injects_seen += 1

    def _fault_inject_ack(self, v: dict[str, Any], t_s: float) -> None:
        self.acks_seen += 1
        self.acks.append(
            {
                "n": self.acks_seen,
                "t_s": t_s,
                "kind": _name(self.choices["FaultKind"], v["FaultKind"]),
                "value": _json_float(float(v["Value"])),
                "status": _name(self.choices["Status"], v["Status"]),
            }
        )

    def _reference_state(self) -> str:
        """``aligned``, ``none`` (no reference given), ``waiting`` (no enabled command yet) or
        ``attached late`` (the controller was ACTIVE before the monitor heard it: k unknown)."""
        if self.reference is None:
            return "none"
        if self._cycle0 is not None:
            return "aligned"
        return "attached late" if self._cycle_raw is not None and not self._saw_disabled else "waiting"

    # ---- output --------------------------------------------------------------------------------
    def status_t0(self) -> float:
        """Run time 0 (s, epoch): the controller's first ACTIVE cycle heard, else the first frame."""
        return self.start_t_s if math.isfinite(self.start_t_s) else self.first_t_s

    def rows_since(self, seq: int) -> dict[str, list[float | None]]:
        """The rows after sequence number ``seq``, by column (NaN as None)."""
        new = [row for s, row in self.rows if s > seq]
        return {f: [_json_float(r[i]) for r in new] for i, f in enumerate(ROW_FIELDS)}

    def status(self, now_s: float | None = None) -> dict[str, Any]:
        """Everything but the rows, JSON-ready. ``now_s``: the time "now" on the frames' clock,
        for the silence check (None: the last frame's time)."""
        lat, r = self._latest, self._rates
        now = self.last_t_s if now_s is None else now_s
        silent_s = now - self.last_t_s if math.isfinite(self.last_t_s) else math.inf
        index = [
            {"slot": s, "j": _json_float(j), "theta": _json_float(th)}
            for s, (j, th, t) in sorted(lat.index.items())
            if now - t <= INDEX_STALE_S
        ]
        values = {k: _json_float(v) for k, v in lat.values.items()}
        values["e_m"] = _json_float(tracking_error(lat.values))
        out: dict[str, Any] = {
            **lat.status,
            **lat.stats,
            "values": values,
            "k_q_true": lat.faults.get("k_q"),
            "stuck": lat.stuck,
            "index": index,
            "verdicts": dict(self.verdicts),
            "frames": self.frames,
            "frames_per_s": round(r.frames_per_s, 1),
            "rejected_per_s": round(r.rejected_per_s, 1),
            "bus_load": round(r.bits_per_s / self.bitrate, 4),
            "aux_flags": lat.aux_flags,
            "nmt": dict(lat.nmt),
            "emcy": [],  # no EMCY frame in the DBC yet: the banner shows codes once there is one
            "injects_seen": self.injects_seen,
            "inject_acks": list(self.acks),
            "failsafe_trips": self.failsafe_trips,
            "t0_s": _json_float(self.status_t0()),
            "t0_from": "controller start" if math.isfinite(self.start_t_s) else "first frame heard",
            "silent_s": _json_float(silent_s) if math.isfinite(silent_s) else None,
            "seq": self.seq,
            "reference": self._reference_state(),
        }
        out["banner"] = banner(out, silent_s)
        return out


def tracking_error(v: dict[str, float]) -> float:
    """x_true − y_m (m), or the sensor's y_s − y_m without PLANT_TRUTH; NaN without y_m."""
    e = v["x_true_m"] - v["y_m_m"]
    return e if math.isfinite(e) else v["y_s_m"] - v["y_m_m"]


def banner(st: dict[str, Any], silent_s: float) -> dict[str, str]:
    """The status banner: ``{"level": ok|warn|fault, "text": …}``, the worst condition first."""
    if silent_s > SILENT_S:
        return {"level": "fault", "text": "no frames on the bus" if math.isinf(silent_s) else "bus silent"}
    state = st.get("state")
    if state is None:
        return {"level": "warn", "text": "no CTRL_STATUS from the controller"}
    if state == "FAULT":
        return {"level": "fault", "text": f"FAULT (fail-safe): {st.get('failsafe_reason', '?')}"}
    if st.get("fallback"):
        return {"level": "warn", "text": f"FALLBACK to nominal: {st.get('fallback_reason', '?')}"}
    if st.get("emcy"):
        return {"level": "warn", "text": "EMCY " + ", ".join(st["emcy"])}
    return {"level": "ok" if state == "ACTIVE" else "warn", "text": state}


_HANDLERS: dict[str, Any] = {
    "SENSOR_POS": MonitorState._sensor_pos,
    "SENSOR_AUX": MonitorState._sensor_aux,
    "VALVE_CMD": MonitorState._valve_cmd,
    "CTRL_STATUS": MonitorState._ctrl_status,
    "CTRL_INDEX": MonitorState._ctrl_index,
    "CTRL_STATS": MonitorState._ctrl_stats,
    "PLANT_TRUTH": MonitorState._plant_truth,
    "PLANT_FAULTS": MonitorState._plant_faults,
    "FAULT_INJECT": MonitorState._fault_inject,
    "FAULT_INJECT_ACK": MonitorState._fault_inject_ack,
    "HEARTBEAT_CTRL": MonitorState._heartbeat_ctrl,
    "HEARTBEAT_EMU": MonitorState._heartbeat_emu,
}
