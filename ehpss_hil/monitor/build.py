"""A monitor's parts from the controller's config (or the shipped defaults without one)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import can

from ..config import CanIds, ControllerConfig
from ..physics.load import load_params
from ..runtime.frameio import process_codec
from .listener import BusListener
from .profiles import monitor_codec
from .reference import ReferenceTrack
from .state import MonitorState, choice_names


def build_listener(
    open_bus: Callable[[], can.BusABC],
    cfg: ControllerConfig | None,
    cfg_path: Path | None,
    bitrate: int,
    netns: str | None = None,
    allow_inject: bool = False,
    capture_dir: Path | None = None,
) -> BusListener:
    """The listener (not started) with its state: the config's DBC, ID layout and protocol
    profile (:mod:`.profiles`), and x_d/y_m from its reference and rate when ``cfg`` is given.
    ``bitrate``: bit/s, for the bus load."""
    dbc, ids, where = (cfg.dbc, cfg.ids, str(cfg_path)) if cfg is not None else ("", CanIds(), "")
    codec = monitor_codec(cfg, cfg_path)
    track = None
    if cfg is not None:
        track = ReferenceTrack(cfg.reference, load_params(cfg.params or None), 1.0 / cfg.rate_hz)
    state = MonitorState(choice_names(codec), track, bitrate=bitrate)
    tx = process_codec(dbc, ids, where) if allow_inject else None
    return BusListener(
        open_bus, codec, state, tx_codec=tx, netns=netns, allow_inject=allow_inject, capture_dir=capture_dir
    )
