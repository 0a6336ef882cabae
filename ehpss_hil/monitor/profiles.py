"""The monitor's codec for every protocol profile: a listen-only dry run of a valve's traffic.

The monitor decodes what it hears with the codec of the controller's config, so a vendor's
frames (``dbc-map``) or a CANopen valve's PDOs (``cia408``) show as the logical signals —
position, spool, coil current, set-point — before anything is enabled:

* ``native`` and ``dbc-map``: the process codec itself (a mapped vendor message classifies to
  the native names in SI units; its E2E is checked the same way);
* ``cia408``: the master's codec, told what a master would know from its own sends
  (:class:`ListenCia408Codec`): each RPDO 1 it hears is the set-point (and control word) the
  echo reports two cycles later, each SYNC it hears the cycle the TPDOs answer. The encoder's
  measuring step is the EDS default (the master reads 0x6005.1 by SDO; a listener sends
  nothing). No load pressure (a CiA 408 valve in spool mode reports none).

The monitor never transmits through these codecs (FAULT_INJECT is native only).
"""

from __future__ import annotations

from pathlib import Path

import can

from ..codec import Decoded, FrameCodec, Verdict
from ..config import CanIds, ControllerConfig
from ..physics.load import load_params
from ..protocol.cia408.codec import Cia408Codec
from ..runtime.frameio import process_codec


class ListenCia408Codec(Cia408Codec):
    """The CiA 408 master's codec fed by what it hears instead of what it sends."""

    def classify(self, frame: can.Message) -> Decoded:
        d = super().classify(frame)
        if d.verdict is not Verdict.OK:
            return d
        if d.name == "VALVE_CMD" and d.values is not None:
            self.control_word = int(d.values["ControlWord"])
            self.encode("VALVE_CMD", {"CurrentSetpoint": d.values["CurrentSetpoint"], "Enable": 1})
        elif d.name == "SYNC":
            self.encode("SYNC", {})
        return d


def monitor_codec(cfg: ControllerConfig | None, cfg_path: Path | None) -> FrameCodec:
    """The codec the monitor decodes with: ``cfg``'s profile (native without a config)."""
    if cfg is None:
        return process_codec("", CanIds(), "")
    where = str(cfg_path or "")
    plant = load_params(cfg.params or None).plant
    codec = process_codec(
        cfg.dbc,
        cfg.ids,
        where,
        cfg.protocol,
        cfg.dbc_map,
        cfg.nodes,
        plant.spool_stroke_m,
        plant.stroke_current_a,
    )
    if isinstance(codec, Cia408Codec):
        listen = ListenCia408Codec(
            cfg.nodes.valve_node,
            cfg.nodes.encoder_node,
            codec.scaling,
            cfg.dbc or None,
            id_base=cfg.ids.id_base,
            node_ids={"HEARTBEAT_CTRL": cfg.ids.controller_node, "HEARTBEAT_EMU": cfg.ids.emulator_node},
            max_delta_counter=cfg.ids.max_delta_counter,
            position_from_valve=cfg.nodes.position_source == "valve",
        )
        return listen
    return codec
