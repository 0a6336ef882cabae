"""The EDS files the project ships for its emulated nodes, loaded through ``canopen``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ... import DATA_DIR
from ...errors import ConfigError

EDS_DIR = DATA_DIR / "eds"
VALVE_EDS = EDS_DIR / "ehpss-valve-cia408.eds"
ENCODER_EDS = EDS_DIR / "ehpss-encoder-cia406.eds"


def load_od(path: str | Path, node_id: int, src: str = "", key: str = "") -> Any:
    """The ``canopen.ObjectDictionary`` of EDS file ``path`` for node ``node_id`` (``$NODEID``
    resolved); a file that is missing or that ``canopen``'s EDS parser refuses is a
    :class:`ConfigError` naming ``key`` of ``src``."""
    from canopen.objectdictionary import import_od

    try:
        return import_od(str(path), node_id)
    except Exception as exc:  # configparser, ValueError, KeyError, OSError from the parser
        raise ConfigError(src, key, f"cannot load EDS {path}: {type(exc).__name__}: {exc}") from exc
