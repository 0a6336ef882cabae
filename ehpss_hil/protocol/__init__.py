"""Protocol profiles: how the controller's logical frames travel on the bus.

A profile is a :class:`~ehpss_hil.codec.FrameCodec`: the controller's loop, the emulator's
process and the lockstep transport encode and classify the logical frames SENSOR_POS, SENSOR_AUX
and VALVE_CMD by their native names and SI signals (:mod:`.logical`), and the profile decides
which bytes carry them. ``native``: our own DBC (``dbc/ehpss.dbc``). ``dbc-map``: a vendor DBC
and a map of the logical signals onto its messages (:mod:`.dbcmap`, checked by :mod:`.mapcheck`).
``cia408``: CANopen with the valve profile CiA 408 and a CiA 406 encoder (:mod:`.cia408`); the
emulator impersonates those nodes (``firmware_sim/canopen_node/``); the controller masters them
(:class:`.cia408.codec.Cia408Codec` maps the logical frames onto their PDOs).
"""

from __future__ import annotations

from ..codec import FrameCodec
from ..config import PROTOCOLS, CanIds, Cia408Config, DbcMap
from ..errors import ConfigError, FrameIdError

__all__ = ["PROTOCOLS", "make_codec"]


def _native(dbc: str, ids: CanIds, src: str) -> FrameCodec:
    if dbc:
        from .mapcheck import check_dbc_file

        check_dbc_file(dbc, src, "dbc")
    try:
        return FrameCodec(
            dbc or None,
            id_base=ids.id_base,
            node_ids={"HEARTBEAT_CTRL": ids.controller_node, "HEARTBEAT_EMU": ids.emulator_node},
            max_delta_counter=ids.max_delta_counter,
        )
    except FrameIdError as exc:
        raise ConfigError(src, "ids.id_base", str(exc)) from exc
    except ValueError as exc:  # FrameError, or cantools on a file that is no DBC
        raise ConfigError(src, "dbc", f"cannot load {dbc}: {exc}") from exc


def make_codec(
    protocol: str,
    dbc: str,
    ids: CanIds,
    src: str,
    dbc_map: DbcMap | None = None,
    cia408: Cia408Config | None = None,
    spool_stroke_m: float = 0.0,
    stroke_current_a: float = 0.0,
) -> FrameCodec:
    """The codec of a process config: ``protocol`` (``native``, ``dbc-map`` with ``dbc_map``, or
    the master's ``cia408`` with its nodes ``cia408`` and the valve's spool stroke (m)), the
    native DBC ``dbc`` (empty: the shipped one) and the ID layout ``ids``. A bad DBC, map, EDS
    or ID layout is a :class:`ConfigError` naming its key (exit 2). ``stroke_current_a``: the
    coil current (A) of the spool's stroke, which a mapped current field must hold."""
    native = _native(dbc, ids, src)
    if protocol == "native":
        return native
    if protocol == "cia408":
        if cia408 is None or spool_stroke_m <= 0.0:
            raise ConfigError(
                src, "protocol", "cia408 needs its nodes (cia408:) and the spool stroke (params)"
            )
        from .cia408.codec import master_codec

        return master_codec(cia408, spool_stroke_m, dbc, ids, src)
    if protocol != "dbc-map" or dbc_map is None:
        raise ConfigError(src, "protocol", f"expected one of {', '.join(PROTOCOLS)} (dbc-map with dbc_map)")
    from .dbcmap import MappedCodec
    from .mapcheck import check_id_clash, resolve_map

    vdb, frames = resolve_map(dbc_map, src, stroke_current_a)
    codec = MappedCodec(
        frames,
        dbc or None,
        id_base=ids.id_base,
        node_ids={"HEARTBEAT_CTRL": ids.controller_node, "HEARTBEAT_EMU": ids.emulator_node},
        max_delta_counter=ids.max_delta_counter,
    )
    check_id_clash(vdb, codec.native_ids(), ids.id_base, src)
    return codec
