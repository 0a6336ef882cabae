"""Typed DBC decoding for tests that read signal values straight from frames with cantools."""

from __future__ import annotations

from cantools.database.can import Message as DbcMessage


def signal_values(msg: DbcMessage, data: bytes | bytearray) -> dict[str, float]:
    """The scaled, numeric signal values of one ``msg`` frame (no value-table names).

    ``Message.decode`` is typed as a union with the container-message result; our DBC has no
    container messages, so this asserts the plain ``{signal: number}`` form and returns it typed.
    """
    v = msg.decode(bytes(data), decode_choices=False)
    assert isinstance(v, dict), f"{msg.name} decoded as a container message"
    out: dict[str, float] = {}
    for k, x in v.items():
        assert isinstance(x, int | float), f"{msg.name}.{k} = {x!r} is not a number"
        out[k] = x
    return out
