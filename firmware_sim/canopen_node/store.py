"""The object values of one emulated CANopen node, with the checks of an SDO access.

Values start from the node's EDS defaults (``canopen``'s parser), overridden by the emulator
config (e.g. the heartbeat time). :meth:`ObjectStore.get_data` / :meth:`ObjectStore.set_data`
are what ``canopen``'s SDO server asks of the node it serves; a bad access raises
``SdoAbortedError`` with the CiA 301 abort code, which the server sends back.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from canopen.objectdictionary import ODArray, ODRecord, ODVariable
from canopen.objectdictionary.datatypes import NUMBER_TYPES
from canopen.sdo import SdoAbortedError

from ehpss_hil.protocol.cia408.objects import ABORT_LENGTH, ABORT_NOT_IN_OD, ABORT_RANGE, ABORT_READ_ONLY

Key = tuple[int, int]
#: sub-index that does not exist (CiA 301)
ABORT_NO_SUBINDEX = 0x0609_0011
#: attempt to read a write-only object
ABORT_WRITE_ONLY = 0x0601_0001


class ObjectStore:
    """Values of the object dictionary ``od`` (a ``canopen.ObjectDictionary``)."""

    def __init__(self, od: Any, overrides: dict[Key, int] | None = None) -> None:
        self.object_dictionary = od  # the name canopen's SdoServer reads
        self._overrides = dict(overrides or {})
        self.values: dict[Key, Any] = {}
        #: called before a write over SDO is stored: ``(index, sub, value)``; may raise
        #: ``SdoAbortedError`` to refuse it
        self.on_write: Callable[[int, int, Any], None] | None = None
        #: objects whose value the profile computes when read (live process values)
        self.live: dict[Key, Callable[[], Any]] = {}
        self.reset(0x0000, 0xFFFF)

    def variables(self) -> list[ODVariable]:
        """Every variable of the dictionary (sub-indices of records and arrays included)."""
        out: list[ODVariable] = []
        for obj in self.object_dictionary.values():
            if isinstance(obj, (ODRecord, ODArray)):
                out.extend(obj.values())
            else:
                out.append(obj)
        return out

    def reset(self, lo: int, hi: int) -> None:
        """Objects ``lo``…``hi`` back to their power-on values (EDS default or config)."""
        for var in self.variables():
            if lo <= var.index <= hi:
                key = (var.index, var.subindex)
                default = var.value if var.value is not None else var.default
                self.values[key] = self._overrides.get(key, default)

    def var(self, index: int, subindex: int) -> ODVariable:
        """The dictionary entry; aborts 0x06020000 (no object) or 0x06090011 (no sub-index)."""
        if index not in self.object_dictionary:
            raise SdoAbortedError(ABORT_NOT_IN_OD)
        obj = self.object_dictionary[index]
        if isinstance(obj, (ODRecord, ODArray)):
            if subindex not in obj:
                raise SdoAbortedError(ABORT_NO_SUBINDEX)
            obj = obj[subindex]
        return obj  # type: ignore[no-any-return]

    def get(self, index: int, subindex: int = 0) -> Any:
        """The value of an object (a live value computed now)."""
        fn = self.live.get((index, subindex))
        return fn() if fn is not None else self.values[(index, subindex)]

    def set(self, index: int, subindex: int, value: Any) -> None:
        """Store a value (the node's own writes: no access check)."""
        self.values[(index, subindex)] = value

    # ---- the interface canopen's SdoServer calls ---------------------------------------------
    def get_data(self, index: int, subindex: int, check_readable: bool = False) -> bytes:
        """The encoded value for an SDO upload."""
        var = self.var(index, subindex)
        if check_readable and not var.readable:
            raise SdoAbortedError(ABORT_WRITE_ONLY)
        return var.encode_raw(self.get(index, subindex))

    def set_data(self, index: int, subindex: int, data: bytes, check_writable: bool = False) -> None:
        """Decode, check and store an SDO download: read-only 0x06010002, a length that is not the
        type's 0x06070010, outside the EDS LowLimit/HighLimit 0x06090030."""
        var = self.var(index, subindex)
        if check_writable and not var.writable:
            raise SdoAbortedError(ABORT_READ_ONLY)
        if var.data_type in NUMBER_TYPES and 8 * len(data) != len(var):
            raise SdoAbortedError(ABORT_LENGTH)
        value = var.decode_raw(bytes(data))
        if isinstance(value, (int, float)) and (
            (var.min is not None and value < var.min) or (var.max is not None and value > var.max)
        ):
            raise SdoAbortedError(ABORT_RANGE)
        if self.on_write is not None:
            self.on_write(index, subindex, value)
        self.values[(index, subindex)] = value
