"""What a receiver makes of one frame: its :class:`Verdict` and the :class:`Decoded` result."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any


class Verdict(IntEnum):
    """Classification of one received frame. Only OK and OK_SOME_LOST carry usable data."""

    OK = 0
    REPEATED = 1
    WRONG_SEQUENCE = 2
    OK_SOME_LOST = 3
    CRC_ERROR = 4
    BAD_DLC = 5
    UNKNOWN_ID = 6
    OUT_OF_RANGE = 7

    @property
    def usable(self) -> bool:
        """True when the frame's data may be acted on."""
        return self in (Verdict.OK, Verdict.OK_SOME_LOST)


@dataclass(slots=True)
class Decoded:
    """A classified frame: its verdict, its DBC name (None if unknown), its physical values and
    its sequence counter's low 4 bits (None: not E2E protected, or not usable)."""

    verdict: Verdict
    name: str | None
    values: dict[str, Any] | None
    timestamp_s: float = 0.0
    counter: int | None = None
