"""A copy of the native DBC with another LSB for some logical signals.

The lockstep simulator quantizes every sample through a DBC's scaling (:mod:`.transport`), and
a vendor DBC reaches the controller through the same conversion (``dbc-map``), so the effect of
a field's resolution on the control loop is measured by running the native frames with that
signal's factor changed: ``ehpss-hil bench resolution`` sweeps it (docs/hardware.md §1).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import cantools
from cantools.database.can import Database

from .. import DEFAULT_DBC
from ..protocol.logical import LOGICAL_SIGNALS


def native_signal(key: str) -> tuple[str, str]:
    """(native frame, native signal) of logical signal ``key`` (``position``, ``coil_current`` …);
    KeyError for a key that is not a scaled logical signal."""
    for ls in LOGICAL_SIGNALS:
        if ls.key == key and ls.resolution is not None:
            return ls.frame, ls.signal
    raise KeyError(key)


def native_lsb(key: str, base: Path = DEFAULT_DBC) -> float:
    """The LSB (SI) of logical signal ``key`` in the DBC ``base`` (native units are SI)."""
    db = cantools.database.load_file(str(base))
    assert isinstance(db, Database)
    frame, signal = native_signal(key)
    return float(db.get_message_by_name(frame).get_signal_by_name(signal).scale)


def rescaled_dbc(lsb_si: Mapping[str, float], out: Path, base: Path = DEFAULT_DBC) -> Path:
    """Write ``base`` to ``out`` with the factor of each logical signal in ``lsb_si`` (key → LSB
    in SI units) replaced; range, width and everything else unchanged. ValueError when a field's
    bits no longer hold its ``[min|max]`` at the new LSB."""
    db = cantools.database.load_file(str(base))
    assert isinstance(db, Database)
    for key, lsb in lsb_si.items():
        frame, signal = native_signal(key)
        sig = db.get_message_by_name(frame).get_signal_by_name(signal)
        span = max(abs(float(sig.minimum or 0.0)), abs(float(sig.maximum or 0.0)))
        if not lsb > 0.0 or span / lsb >= 1 << (sig.length - 1):
            raise ValueError(
                f"{frame}.{signal}: an LSB of {lsb:g} does not fit ±{span:g} in {sig.length} bits"
            )
        sig.scale = lsb
    out.write_text(db.as_dbc_string())
    return out
