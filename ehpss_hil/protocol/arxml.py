"""The DBC as an AUTOSAR 4 system description (ARXML) that ``cantools.database.load_file`` loads.

A generic DBC → ARXML conversion (canmatrix's) names every AUTOSAR element after its DBC signal,
so the ``CRC`` and ``Counter`` of each E2E-protected message become one path
(``/Cluster/CAN/CAN/CRC`` several times: cantools refuses the file); it writes integer base
types without an encoding (cantools refuses those too) and flattens multiplexed messages into
overlapping signals. This writer makes what cantools reads:

- one CAN-FRAME and one PDU per message, named as the message; a multiplexed message is a
  MULTIPLEXED-I-PDU (a static part, one dynamic-part alternative per multiplexer value, the
  selector in each alternative as AUTOSAR has it; cantools names the selector
  ``<MESSAGE>_selector1``);
- a signal whose name occurs in more than one message is exported as ``<MESSAGE>_<signal>``
  (:func:`export_names`): AUTOSAR short names are unique per package, and cantools names a
  signal after its I-SIGNAL;
- scaling as a LINEAR compu method (or SCALE_LINEAR_AND_TEXTTABLE with the DBC's value
  table), the range as its raw limits, the unit, the comments, signed/unsigned/IEEE754 base
  types; START-POSITION is the DBC start bit as cantools reads it for either byte order;
- a message's ``E2E_DataIDs`` attribute as the AUTOSAR E2E profile 2 DataID list of its
  signal group (not for a multiplexed message: cantools reads E2E from a plain PDU only).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from cantools.database.can import Database, Message, Signal

from ..errors import ConfigError, OutputError

#: AUTOSAR 4 schema namespace (cantools reads the major version from it)
NAMESPACE = "http://autosar.org/schema/r4.0"
_XSI = "http://www.w3.org/2001/XMLSchema-instance"
SCHEMA = "AUTOSAR_4-3-0.xsd"
#: the DBC attribute of the E2E DataID list (16 values, one per counter value)
E2E_ATTRIBUTE = "E2E_DataIDs"
E2E_PROFILE = "PROFILE_02"
CLUSTER = "CAN"

_Names = dict[tuple[str, str], str]
_CLOSED = {"INTERVAL-TYPE": "CLOSED"}


def export_names(db: Database) -> _Names:
    """(message, signal) → the signal's AUTOSAR short name: the DBC name, or
    ``<MESSAGE>_<signal>`` when that name occurs in more than one message."""
    seen = Counter(s.name for m in db.messages for s in m.signals)
    names = {
        (m.name, s.name): (f"{m.name}_{s.name}" if seen[s.name] > 1 else s.name)
        for m in db.messages
        for s in m.signals
    }
    clash = [n for n, k in Counter(names.values()).items() if k > 1]
    if clash:
        raise ConfigError("", "signals", f"cannot give these signals unique ARXML names: {clash}")
    return names


def _sub(parent: ET.Element, tag: str, text: Any = None, attrs: dict[str, str] | None = None) -> ET.Element:
    """A child element; a number's text is its ``repr`` (exact for floats)."""
    e = ET.SubElement(parent, tag, attrs or {})
    if text is not None:
        e.text = text if isinstance(text, str) else repr(text)
    return e


def _ref(parent: ET.Element, tag: str, dest: str, path: str) -> ET.Element:
    return _sub(parent, tag, path, {"DEST": dest})


def _package(root: ET.Element, name: str) -> ET.Element:
    pkg = _sub(root, "AR-PACKAGE")
    _sub(pkg, "SHORT-NAME", name)
    return _sub(pkg, "ELEMENTS")


def _desc(parent: ET.Element, comment: str | None) -> None:
    if comment:
        _sub(_sub(parent, "DESC"), "L-2", comment, {"L": "FOR-ALL"})


def _conditional(parent: ET.Element, tag: str) -> ET.Element:
    """``<tag>/SW-DATA-DEF-PROPS-VARIANTS/SW-DATA-DEF-PROPS-CONDITIONAL``."""
    return _sub(_sub(_sub(parent, tag), "SW-DATA-DEF-PROPS-VARIANTS"), "SW-DATA-DEF-PROPS-CONDITIONAL")


def _base_type(sig: Signal) -> tuple[str, int, str]:
    """(name, size in bits, BASE-TYPE-ENCODING) of the signal's raw value."""
    if sig.is_float:
        size = 32 if sig.length <= 32 else 64
        return f"float{size}", size, "IEEE754"
    size = next(n for n in (8, 16, 32, 64) if sig.length <= n) if sig.length <= 64 else sig.length
    return (f"sint{size}", size, "2C") if sig.is_signed else (f"uint{size}", size, "NONE")


class _Writer:
    """Builds the element tree of one database (see the module docstring)."""

    def __init__(self, db: Database) -> None:
        self.db = db
        self.names = export_names(db)
        self.root = ET.Element(
            "AUTOSAR", {"xmlns": NAMESPACE, "xmlns:xsi": _XSI, "xsi:schemaLocation": f"{NAMESPACE} {SCHEMA}"}
        )
        packages = _sub(self.root, "AR-PACKAGES")
        self.cluster = _package(packages, "Cluster")
        self.frames = _package(packages, "Frames")
        self.pdus = _package(packages, "PDUs")
        self.isignals = _package(packages, "ISignals")
        self.groups = _package(packages, "SignalGroups")
        self.system = _package(packages, "SystemSignals")
        self.compu = _package(packages, "CompuMethods")
        self.units_pkg = _package(packages, "Units")
        self.types = _package(packages, "BaseTypes")
        self.transformers = _package(packages, "Transformers")
        self.units: dict[str, str] = {}
        self.base_types: set[str] = set()
        self.signals_done: set[str] = set()

    def build(self) -> ET.Element:
        cluster = _sub(self.cluster, "CAN-CLUSTER")
        _sub(cluster, "SHORT-NAME", CLUSTER)
        cond = _sub(_sub(cluster, "CAN-CLUSTER-VARIANTS"), "CAN-CLUSTER-CONDITIONAL")
        channel = _sub(_sub(cond, "PHYSICAL-CHANNELS"), "CAN-PHYSICAL-CHANNEL")
        _sub(channel, "SHORT-NAME", CLUSTER)
        triggerings = _sub(channel, "FRAME-TRIGGERINGS")
        if any(self._data_ids(m) for m in self.db.messages):
            self._transformer()
        for msg in self.db.messages:
            self._frame(triggerings, msg)
        return self.root

    def _frame(self, triggerings: ET.Element, msg: Message) -> None:
        trig = _sub(triggerings, "CAN-FRAME-TRIGGERING")
        _sub(trig, "SHORT-NAME", msg.name)
        behaviour = "CAN-FD" if msg.is_fd else "CAN-20"
        _sub(trig, "CAN-ADDRESSING-MODE", "EXTENDED" if msg.is_extended_frame else "STANDARD")
        _sub(trig, "CAN-FRAME-RX-BEHAVIOR", behaviour)
        _sub(trig, "CAN-FRAME-TX-BEHAVIOR", behaviour)
        _ref(trig, "FRAME-REF", "CAN-FRAME", f"/Frames/{msg.name}")
        _sub(trig, "IDENTIFIER", str(msg.frame_id))
        frame = _sub(self.frames, "CAN-FRAME")
        _sub(frame, "SHORT-NAME", msg.name)
        _desc(frame, msg.comment)
        _sub(frame, "FRAME-LENGTH", str(msg.length))
        mapping = _sub(_sub(frame, "PDU-TO-FRAME-MAPPINGS"), "PDU-TO-FRAME-MAPPING")
        _sub(mapping, "SHORT-NAME", msg.name)
        _sub(mapping, "PACKING-BYTE-ORDER", "MOST-SIGNIFICANT-BYTE-LAST")
        muxes = [s for s in msg.signals if s.is_multiplexer]
        dest = "MULTIPLEXED-I-PDU" if muxes else "I-SIGNAL-I-PDU"
        _ref(mapping, "PDU-REF", dest, f"/PDUs/{msg.name}")
        _sub(mapping, "START-POSITION", "0")
        if muxes:
            self._multiplexed_pdu(msg, muxes)
        else:
            self._pdu(msg, msg.name, msg.signals, self._data_ids(msg))

    def _pdu(self, msg: Message, name: str, signals: Iterable[Signal], data_ids: list[int] | None) -> None:
        pdu = _sub(self.pdus, "I-SIGNAL-I-PDU")
        _sub(pdu, "SHORT-NAME", name)
        _sub(pdu, "LENGTH", str(msg.length))
        mappings = _sub(pdu, "I-SIGNAL-TO-PDU-MAPPINGS")
        members = []
        for sig in signals:
            members.append(self._signal(msg, sig))
            m = _sub(mappings, "I-SIGNAL-TO-I-PDU-MAPPING")
            _sub(m, "SHORT-NAME", sig.name)
            _ref(m, "I-SIGNAL-REF", "I-SIGNAL", f"/ISignals/{members[-1]}")
            order = (
                "MOST-SIGNIFICANT-BYTE-FIRST"
                if sig.byte_order == "big_endian"
                else "MOST-SIGNIFICANT-BYTE-LAST"
            )
            _sub(m, "PACKING-BYTE-ORDER", order)
            _sub(m, "START-POSITION", str(sig.start))
        if data_ids is not None:
            m = _sub(mappings, "I-SIGNAL-TO-I-PDU-MAPPING")
            _sub(m, "SHORT-NAME", f"{name}_E2E")
            _ref(m, "I-SIGNAL-GROUP-REF", "I-SIGNAL-GROUP", f"/SignalGroups/{name}")
            self._group(name, members, data_ids)
        _sub(pdu, "UNUSED-BIT-PATTERN", "0")

    def _multiplexed_pdu(self, msg: Message, muxes: list[Signal]) -> None:
        if len(muxes) > 1 or any(s.multiplexer_signal not in (None, muxes[0].name) for s in msg.signals):
            raise ConfigError("", msg.name, "nested multiplexing cannot be exported to ARXML")
        mux = muxes[0]
        alternatives: dict[int, list[Signal]] = {}
        for s in msg.signals:
            if s.multiplexer_signal is not None:
                for i in s.multiplexer_ids or ():
                    alternatives.setdefault(i, []).append(s)
        pdu = _sub(self.pdus, "MULTIPLEXED-I-PDU")
        _sub(pdu, "SHORT-NAME", msg.name)
        _sub(pdu, "LENGTH", str(msg.length))
        alts = _sub(_sub(_sub(pdu, "DYNAMIC-PARTS"), "DYNAMIC-PART"), "DYNAMIC-PART-ALTERNATIVES")
        for code, signals in sorted(alternatives.items()):
            alt = _sub(alts, "DYNAMIC-PART-ALTERNATIVE")
            _ref(alt, "I-PDU-REF", "I-SIGNAL-I-PDU", f"/PDUs/{msg.name}_m{code}")
            _sub(alt, "SELECTOR-FIELD-CODE", str(code))
            self._pdu(msg, f"{msg.name}_m{code}", [mux, *signals], None)
        big = mux.byte_order == "big_endian"
        _sub(
            pdu,
            "SELECTOR-FIELD-BYTE-ORDER",
            "MOST-SIGNIFICANT-BYTE-FIRST" if big else "MOST-SIGNIFICANT-BYTE-LAST",
        )
        _sub(pdu, "SELECTOR-FIELD-LENGTH", str(mux.length))
        _sub(pdu, "SELECTOR-FIELD-START-POSITION", str(mux.start))
        static = [s for s in msg.signals if s.multiplexer_signal is None and not s.is_multiplexer]
        if static:
            part = _sub(_sub(pdu, "STATIC-PARTS"), "STATIC-PART")
            _ref(part, "I-PDU-REF", "I-SIGNAL-I-PDU", f"/PDUs/{msg.name}_static")
            self._pdu(msg, f"{msg.name}_static", static, None)

    def _signal(self, msg: Message, sig: Signal) -> str:
        """The I-SIGNAL, SYSTEM-SIGNAL and COMPU-METHOD of ``sig`` (once); its short name."""
        name = self.names[(msg.name, sig.name)]
        if name in self.signals_done:
            return name
        self.signals_done.add(name)
        isig = _sub(self.isignals, "I-SIGNAL")
        _sub(isig, "SHORT-NAME", name)
        if sig.raw_initial is not None:
            init = _sub(_sub(isig, "INIT-VALUE"), "NUMERICAL-VALUE-SPECIFICATION")
            _sub(init, "VALUE", sig.raw_initial)
        _sub(isig, "LENGTH", str(sig.length))
        type_name, size, encoding = _base_type(sig)
        _ref(
            _conditional(isig, "NETWORK-REPRESENTATION-PROPS"),
            "BASE-TYPE-REF",
            "SW-BASE-TYPE",
            f"/BaseTypes/{type_name}",
        )
        _ref(isig, "SYSTEM-SIGNAL-REF", "SYSTEM-SIGNAL", f"/SystemSignals/{name}")
        if type_name not in self.base_types:
            self.base_types.add(type_name)
            bt = _sub(self.types, "SW-BASE-TYPE")
            _sub(bt, "SHORT-NAME", type_name)
            _sub(bt, "CATEGORY", "FIXED_LENGTH")
            _sub(bt, "BASE-TYPE-SIZE", str(size))
            _sub(bt, "BASE-TYPE-ENCODING", encoding)
        system = _sub(self.system, "SYSTEM-SIGNAL")
        _sub(system, "SHORT-NAME", name)
        _desc(system, sig.comment)
        _ref(
            _conditional(system, "PHYSICAL-PROPS"),
            "COMPU-METHOD-REF",
            "COMPU-METHOD",
            f"/CompuMethods/{name}",
        )
        self._compu_method(name, sig)
        return name

    def _compu_method(self, name: str, sig: Signal) -> None:
        cm = _sub(self.compu, "COMPU-METHOD")
        _sub(cm, "SHORT-NAME", name)
        choices = sig.conversion.choices
        _sub(cm, "CATEGORY", "SCALE_LINEAR_AND_TEXTTABLE" if choices else "LINEAR")
        if sig.unit:
            _ref(cm, "UNIT-REF", "UNIT", f"/Units/{self._unit(sig.unit)}")
        scales = _sub(_sub(cm, "COMPU-INTERNAL-TO-PHYS"), "COMPU-SCALES")
        for raw, text in (choices or {}).items():
            scale = _sub(scales, "COMPU-SCALE")
            _sub(scale, "LOWER-LIMIT", str(raw), _CLOSED)
            _sub(scale, "UPPER-LIMIT", str(raw), _CLOSED)
            _sub(_sub(scale, "COMPU-CONST"), "VT", str(text))
        scale = _sub(scales, "COMPU-SCALE")
        for tag, value in (("LOWER-LIMIT", sig.minimum), ("UPPER-LIMIT", sig.maximum)):
            if value is not None:  # the range as raw limits: cantools scales them back
                _sub(scale, tag, (value - sig.offset) / sig.scale, _CLOSED)
        coeffs = _sub(scale, "COMPU-RATIONAL-COEFFS")
        numerator = _sub(coeffs, "COMPU-NUMERATOR")
        _sub(numerator, "V", sig.offset)
        _sub(numerator, "V", sig.scale)
        _sub(_sub(coeffs, "COMPU-DENOMINATOR"), "V", "1")

    def _unit(self, text: str) -> str:
        name = self.units.get(text)
        if name is None:
            name = self.units[text] = f"UNIT_{len(self.units)}"
            unit = _sub(self.units_pkg, "UNIT")
            _sub(unit, "SHORT-NAME", name)
            _sub(unit, "DISPLAY-NAME", text)
        return name

    def _data_ids(self, msg: Message) -> list[int] | None:
        """The message's E2E DataID list from its DBC attribute (a plain PDU only), or None."""
        attrs = msg.dbc.attributes if msg.dbc is not None else {}
        attr = attrs.get(E2E_ATTRIBUTE)
        if attr is None or not attr.value or any(s.is_multiplexer for s in msg.signals):
            return None
        return [int(v) for v in str(attr.value).split(",")]

    def _group(self, name: str, members: list[str], data_ids: list[int]) -> None:
        group = _sub(self.groups, "I-SIGNAL-GROUP")
        _sub(group, "SHORT-NAME", name)
        refs = _sub(group, "I-SIGNAL-REFS")
        for m in members:
            _ref(refs, "I-SIGNAL-REF", "I-SIGNAL", f"/ISignals/{m}")
        props = _sub(
            _sub(
                _sub(
                    _sub(group, "TRANSFORMATION-I-SIGNAL-PROPSS"), "END-TO-END-TRANSFORMATION-I-SIGNAL-PROPS"
                ),
                "END-TO-END-TRANSFORMATION-I-SIGNAL-PROPS-VARIANTS",
            ),
            "END-TO-END-TRANSFORMATION-I-SIGNAL-PROPS-CONDITIONAL",
        )
        _ref(props, "TRANSFORMER-REF", "TRANSFORMATION-TECHNOLOGY", f"/Transformers/{E2E_PROFILE}")
        ids = _sub(props, "DATA-IDS")
        for d in data_ids:
            _sub(ids, "DATA-ID", str(d))

    def _transformer(self) -> None:
        tech = _sub(self.transformers, "TRANSFORMATION-TECHNOLOGY")
        _sub(tech, "SHORT-NAME", E2E_PROFILE)
        desc = _sub(_sub(tech, "TRANSFORMATION-DESCRIPTIONS"), "END-TO-END-TRANSFORMATION-DESCRIPTION")
        _sub(desc, "PROFILE-NAME", E2E_PROFILE)


def to_arxml(db: Database) -> bytes:
    """``db`` as an AUTOSAR 4 ARXML document (UTF-8)."""
    root = _Writer(db).build()
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def export_arxml(dbc: Path, out: Path) -> Database:
    """Write the ARXML of DBC file ``dbc`` to ``out``; returns the DBC's database. A DBC that
    cannot be loaded is a :class:`ConfigError`, an output that cannot be written an
    :class:`OutputError` (both exit 2)."""
    import cantools

    try:
        db = cantools.database.load_file(str(dbc))
    except (OSError, cantools.database.UnsupportedDatabaseFormatError) as exc:
        raise ConfigError("command line", "--dbc", f"cannot load {dbc}: {exc}") from exc
    if not isinstance(db, Database):
        raise ConfigError("command line", "--dbc", f"{dbc} is not a CAN database")
    data = to_arxml(db)
    try:
        out.write_bytes(data)
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from exc
    return db
