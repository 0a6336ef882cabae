"""The emulator's loop for ``protocol: cia408``: the plant behind a CiA 408 valve node and a
CiA 406 encoder node (:mod:`.canopen_node`).

Realtime, each period k (fixed deadline grid, plant time t = k·Ts): drain RX without blocking →
each frame to both nodes (NMT, SDO, RPDO, the master's heartbeat), SYNCs counted → the
scenario's ``device_fault`` events due → the nodes' clocks (heartbeats, timeouts) → the valve's
current (ACTIVE: set-point × full scale, else 0 A) → measure y[k]: spool actual and position
value → one round of synchronous TPDOs per SYNC received → PLANT_TRUTH (``truth``: the native
DBC frame, for the bench's judgement of the piston; no CANopen node sends it) → advance the plant
over [k, k+1). The TPDOs answering a SYNC thus carry the sample of the period in which it arrived.

When the plant cannot advance (an FMU's step failed: PlantStepError) the valve does what a real
one does on an internal fault: a persistent FAULT with EMCY 0x6100 (its status word shows it in
every TPDO, 0 A), so the master sees a fault and fails safe. The plant is no longer measured or
advanced; the nodes keep running on the loop's clock (NMT, SDO, heartbeats, TPDOs with the last
sample's values: a valve in FAULT centres its spool, the piston holds); PLANT_TRUTH stops; the
reason is logged on one line and kept for the summary (``plant_failure``), and the emulator
exits 1 at the end of its run.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

from ehpss_hil.codec import FrameCodec
from ehpss_hil.config import Cia408Config
from ehpss_hil.emulation import PlantEmulation, SensorSample
from ehpss_hil.errors import PlantStepError
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.identity import identity_overrides
from ehpss_hil.protocol.cia408.objects import CONSUMER_HEARTBEAT, PRODUCER_HEARTBEAT, RPDO_COMM
from ehpss_hil.runtime.rawio import RawFrameIO
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.runtime.stats import LoopStats

from .canopen_node.encoder import EncoderNode
from .canopen_node.node import CanopenSlave
from .canopen_node.valve import ValveNode
from .periods import run_periods

log = logging.getLogger("firmware_sim")


@dataclass(frozen=True)
class CanopenOptions:
    """Run options: ``stats_capacity`` samples of the loop statistics; ``truth``: the native
    codec whose PLANT_TRUTH goes out each period (None: none)."""

    stats_capacity: int = 600_000
    truth: FrameCodec | None = None


def build_nodes(
    c: Cia408Config, valve_od: Any, encoder_od: Any, io: RawFrameIO, stroke_m: float
) -> tuple[ValveNode, EncoderNode]:
    """The two nodes from the config and their object dictionaries; the config's times are the
    power-on values of 0x1017, 0x1016.1 and 0x1400.5, its identities (where given) 0x1018's."""
    hb = {(PRODUCER_HEARTBEAT, 0): c.heartbeat_time_ms}
    valve = ValveNode(
        c.valve_node,
        valve_od,
        io.send,
        c.full_scale_current_a,
        stroke_m,
        {
            **hb,
            (CONSUMER_HEARTBEAT, 1): (c.master_node << 16) | c.master_heartbeat_timeout_ms
            if c.master_heartbeat_timeout_ms
            else 0,
            (RPDO_COMM, 5): c.setpoint_timeout_ms,
            **identity_overrides(c.valve_identity),
        },
    )
    encoder = EncoderNode(
        c.encoder_node, encoder_od, io.send, {**hb, **identity_overrides(c.encoder_identity)}
    )
    return valve, encoder


class CanopenEmulatorProcess:
    """The emulated plant with its valve and encoder nodes on one bus (periods of ``emu.ts_s``)."""

    def __init__(
        self,
        emu: PlantEmulation,
        io: RawFrameIO,
        valve: ValveNode,
        encoder: EncoderNode,
        opts: CanopenOptions,
    ) -> None:
        self.emu = emu
        self.io = io
        self.valve = valve
        self.encoder = encoder
        self.nodes: tuple[CanopenSlave, ...] = (valve, encoder)
        self.stats = LoopStats(opts.stats_capacity)
        self._device_faults = emu.scenario.device_faults()
        self.periods = 0
        self.skipped_periods = 0
        self.syncs = 0
        self.unused_frames = 0
        self.applied_a = 0.0
        #: why the plant stopped (an FMU's failed step), or "" while it runs
        self.plant_failure = ""
        self._truth = opts.truth
        self._truth_bounds = opts.truth.signal_bounds("PLANT_TRUTH") if opts.truth is not None else {}

    @property
    def t_s(self) -> float:
        """Loop time of the current period (s): the plant's time k·Ts while the plant runs (one
        plant sample per period); it goes on after a plant failure."""
        return self.periods * self.emu.ts_s

    def boot(self) -> None:
        """Power-on of both nodes: boot-up messages, PRE-OPERATIONAL."""
        for node in self.nodes:
            node.boot(self.t_s)

    def _receive(self) -> list[int]:
        """Hand every pending frame to the nodes; returns the data lengths of the SYNCs among
        them (0: a well-formed SYNC)."""
        syncs: list[int] = []
        t = self.t_s
        for msg in self.io.drain():
            if msg.arbitration_id == cobid.SYNC:
                syncs.append(len(msg.data))
                continue
            if msg.is_extended_id or msg.is_remote_frame:
                self.unused_frames += 1
                continue
            data = bytes(msg.data)
            used = [node.on_frame(msg.arbitration_id, data, t) for node in self.nodes]
            if not any(used):
                self.unused_frames += 1
        return syncs

    def _due_faults(self) -> None:
        while self._device_faults and self._device_faults[0][0] <= self.periods:
            _, code = self._device_faults.pop(0)
            log.info("t=%.4f s: device fault 0x%04X", self.t_s, code)
            self.valve.inject_fault(code)

    def step_period(self, skipped: int = 0) -> float:
        """One realtime period (no waiting); returns the current applied over it (A). Periods
        the loop slept through (``skipped``) advance the plant with the same current."""
        syncs = self._receive()
        self._due_faults()
        for node in self.nodes:
            node.tick(self.t_s)
        current = self.valve.current_a()
        y: SensorSample | None = None
        if self.plant_failure:
            self.periods += skipped
            self.skipped_periods += skipped
        else:
            start = self.periods
            try:
                y = self._measure(current, skipped)
            except PlantStepError as exc:  # in a skipped period: the rest of them counted too
                self.skipped_periods += start + skipped - self.periods
                self.periods = start + skipped
                self._plant_failed(exc)
        for length in syncs:
            for node in self.nodes:
                node.on_sync(length)
        self.syncs += syncs.count(0)
        if y is not None and self._truth is not None:
            self._send_truth(y.true_position_m, y.true_spool_m, bool(y.faults.stuck))
        if y is not None:
            try:
                self.applied_a = self.emu.advance(current)
            except PlantStepError as exc:
                self._plant_failed(exc)
        if self.plant_failure:
            self.applied_a = 0.0
        self.periods += 1
        self.io.idle()
        return self.applied_a

    def _measure(self, current: float, skipped: int) -> SensorSample:
        """The periods slept through (the plant advanced with ``current``), then this period's
        sample, handed to the nodes and returned."""
        for _ in range(skipped):
            self.emu.measure()  # the noise streams stay on the sample grid
            self.emu.advance(current)
            self.skipped_periods += 1
            self.periods += 1
        y = self.emu.measure()
        self.valve.measure(y.spool_m)
        self.valve.measure_position(y.position_m)
        self.encoder.measure(y.position_m)
        return y

    def _plant_failed(self, exc: PlantStepError) -> None:
        """The plant cannot advance: the valve's persistent internal fault (EMCY 0x6100), the
        reason on one line and in the summary (module docstring)."""
        self.plant_failure = str(exc)
        log.error(
            "t=%.4f s: %s; plant stopped, valve %d in FAULT (fail-safe: EMCY, status word)",
            self.t_s,
            exc,
            self.valve.node_id,
        )
        self.valve.internal_fault()

    def _send_truth(self, position_m: float, spool_m: float, stuck: bool) -> None:
        """PLANT_TRUTH of this sample (values clipped to the DBC's ranges)."""
        assert self._truth is not None
        values = {"Position": position_m, "SpoolActual": spool_m, "Stuck": int(stuck)}
        for sig, (lo, hi) in self._truth_bounds.items():
            if sig in values:
                values[sig] = min(hi, values[sig]) if hi is not None else values[sig]
                values[sig] = max(lo, values[sig]) if lo is not None else values[sig]
        msg = self._truth.encode("PLANT_TRUTH", values)
        self.io.send(msg.arbitration_id, bytes(msg.data))

    def run_realtime(self, stop: StopFlag, n_periods: int | None = None) -> None:
        """Boot the nodes, then run on the deadline grid until ``stop`` or ``n_periods``."""
        self.boot()
        run_periods(self.emu.ts_s, self.step_period, lambda: self.periods, self.stats, stop, n_periods)

    def summary(self) -> dict[str, Any]:
        """Counters and period statistics (JSON-able)."""
        v = self.valve
        return {
            "periods": self.periods,
            "skipped_periods": self.skipped_periods,
            "frames_sent": {f"0x{k:03X}": n for k, n in sorted(self.io.sent.items())},
            "tx_errors": self.io.tx_errors,
            "frames_received": self.io.received,
            "unused_frames": self.unused_frames,
            "syncs": self.syncs,
            "nodes": {
                f"{type(n).__name__}:{n.node_id}": {
                    "nmt": n.nmt.name,
                    "sdo_requests": n.sdo_requests,
                    "rpdos": n.rpdos,
                    "tpdos": n.tpdos,
                    "emcy": n.emcy_sent,
                    "bad_length_frames": n.bad_length_frames,
                }
                for n in self.nodes
            },
            "valve_state": v.device.state.name,
            "plant_failure": self.plant_failure,
            "valve_transitions": v.device.transitions,
            "stats": self.stats.summary(),
        }
