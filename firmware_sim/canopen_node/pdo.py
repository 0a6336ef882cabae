"""PDO mappings read from a node's mapping objects (0x1600…/0x1A00…), packed and unpacked.

A mapping entry is the UNSIGNED32 ``index << 16 | sub << 8 | length in bits``; a PDO carries
the mapped objects back to back, little-endian, at most 64 bits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from canopen.objectdictionary import ODVariable
from canopen.sdo import SdoAbortedError

from .store import ObjectStore

#: object cannot be mapped to the PDO / the number and length of the mapped objects exceed 64 bits
ABORT_NOT_MAPPABLE = 0x0604_0041
ABORT_PDO_LENGTH = 0x0604_0042
#: entries a mapping object holds and bits a classic CAN PDO carries
MAX_ENTRIES = 8
MAX_BITS = 64


def decode_entry(entry: int) -> tuple[int, int, int]:
    """``(index, sub-index, bits)`` of a mapping entry."""
    return entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF


@dataclass(frozen=True)
class PdoMapping:
    """The mapped variables of one PDO, in order."""

    variables: tuple[ODVariable, ...]

    @property
    def length(self) -> int:
        """Bytes the PDO carries."""
        return sum(len(v) for v in self.variables) // 8

    def pack(self, store: ObjectStore) -> bytes:
        """The PDO's data from the store's current values."""
        return b"".join(v.encode_raw(store.get(v.index, v.subindex)) for v in self.variables)

    def unpack(self, data: bytes) -> list[tuple[ODVariable, Any]] | None:
        """The mapped values of a received PDO; None when it is shorter than the mapping."""
        if len(data) < self.length:
            return None
        out, pos = [], 0
        for v in self.variables:
            n = len(v) // 8
            out.append((v, v.decode_raw(data[pos : pos + n])))
            pos += n
        return out


def check_entry(store: ObjectStore, entry: int) -> None:
    """Refuse (SDO abort) a mapping entry naming no mappable object of its own length."""
    if entry == 0:
        return
    index, sub, bits = decode_entry(entry)
    var = store.var(index, sub)
    if not var.pdo_mappable or len(var) != bits:
        raise SdoAbortedError(ABORT_NOT_MAPPABLE)


def read_mapping(store: ObjectStore, map_index: int) -> PdoMapping:
    """The mapping object ``map_index`` as it stands (sub 0 = number of entries)."""
    n = int(store.get(map_index, 0))
    variables = []
    for sub in range(1, min(n, MAX_ENTRIES) + 1):
        entry = int(store.get(map_index, sub))
        if entry:
            index, s, _ = decode_entry(entry)
            variables.append(store.var(index, s))
    mapping = PdoMapping(tuple(variables))
    if mapping.length * 8 > MAX_BITS:
        raise SdoAbortedError(ABORT_PDO_LENGTH)
    return mapping
