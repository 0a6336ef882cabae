"""The undocumented parts of cantools the code relies on, pinned so that a cantools that changes
them fails here, loudly, instead of the codec silently taking its slow path or drifting by one
LSB: the ``cantools.database.conversion`` classes (names, constructors, the factory's choice of
class, the attributes read, and the arithmetic of the methods :mod:`ehpss_hil.codec.layout`
writes out and :mod:`ehpss_hil.sim.transport` calls), and cantools' bound below its next major.

Also python-can's socketcan constants module, which :func:`ehpss_hil.bus.suppress_own_echoes`
imports (checked here too on hosts without SocketCAN). python-can's udp_multicast internals:
``tests/test_bus_udp_boundary.py``; canopen's ``SdoServer`` over the emulated nodes' own object
store: ``tests/test_cia408_master.py``; ``distributed.comm``'s address parsing:
``tests/test_campaign.py``."""

from __future__ import annotations

import inspect
import tomllib
from collections import OrderedDict
from pathlib import Path
from typing import Any

import cantools
import pytest
from cantools.database.conversion import (
    BaseConversion,
    IdentityConversion,
    LinearConversion,
    LinearIntegerConversion,
    NamedSignalConversion,
)

from ehpss_hil import DEFAULT_DBC
from ehpss_hil.codec.layout import (
    _IDENTITY,
    _LINEAR,
    _LINEAR_INT,
    BitLayout,
    _compile,
    _conversion,
    _raw_lines,
)

ROOT = Path(__file__).resolve().parent.parent
VENDOR_DBC = DEFAULT_DBC.parent / "vendor-example.dbc"


def test_cantools_is_bounded_below_its_next_major_version() -> None:
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (spec,) = [d for d in deps if d.replace(" ", "").startswith("cantools")]
    bound = spec.replace(" ", "").split("<")[1]
    assert int(cantools.__version__.split(".")[0]) < int(bound) == int(cantools.__version__.split(".")[0]) + 1


@pytest.mark.parametrize(
    ("cls", "params"),
    [
        (IdentityConversion, ["is_float"]),
        (LinearIntegerConversion, ["scale", "offset"]),
        (LinearConversion, ["scale", "offset", "is_float"]),
        (NamedSignalConversion, ["scale", "offset", "choices", "is_float"]),
    ],
)
def test_the_conversion_classes_and_their_constructors(cls: type, params: list[str]) -> None:
    assert issubclass(cls, BaseConversion)
    assert list(inspect.signature(cls).parameters) == params


@pytest.mark.parametrize(
    ("kwargs", "cls", "scale", "offset", "is_float"),
    [
        ({"scale": 1, "offset": 0}, IdentityConversion, 1, 0, False),
        ({"scale": 1, "offset": 0, "is_float": True}, IdentityConversion, 1, 0, True),
        ({"scale": 10, "offset": -5}, LinearIntegerConversion, 10, -5, False),
        ({"scale": 2.0, "offset": 3.0}, LinearIntegerConversion, 2, 3, False),
        ({"scale": 1e-7, "offset": 0}, LinearConversion, 1e-7, 0, False),
        ({"scale": 10, "offset": 1, "is_float": True}, LinearConversion, 10, 1, True),
        ({"scale": 0.5, "offset": 0, "choices": {0: "off", 1: "on"}}, NamedSignalConversion, 0.5, 0, False),
    ],
)
def test_the_factory_picks_the_class_the_layout_expects(
    kwargs: dict[str, Any], cls: type, scale: float, offset: float, is_float: bool
) -> None:
    conv = BaseConversion.factory(**kwargs)
    assert type(conv) is cls
    assert (conv.scale, conv.offset, conv.is_float) == (scale, offset, is_float)
    assert conv.choices == kwargs.get("choices")


def _layout_to_raw(kind: int, raw_float: bool, scale: Any, offset: Any) -> Any:
    """The physical → raw expression :mod:`ehpss_hil.codec.layout` compiles for a field."""
    return _compile("to_raw", "v", [*_raw_lines(kind, raw_float, 0), "return r"], {"S0": scale, "O0": offset})


#: values on, between and exactly half-way between raw steps, negative and large
_VALUES = [
    0,
    0.0,
    -0.0,
    1,
    -1,
    2.5,
    3.5,
    -2.5,
    7,
    1e-7,
    1.5e-7,
    2.5e-7,
    -3.5e-7,
    0.12345678,
    1e6 + 0.5,
    -123456.75,
]


@pytest.mark.parametrize(
    ("conv", "kind"),
    [
        (IdentityConversion(is_float=False), _IDENTITY),
        (IdentityConversion(is_float=True), _IDENTITY),
        (LinearIntegerConversion(scale=10, offset=-5), _LINEAR_INT),
        (LinearIntegerConversion(scale=1, offset=3), _LINEAR_INT),
        (LinearConversion(scale=1e-7, offset=0, is_float=False), _LINEAR),
        (LinearConversion(scale=0.2, offset=-1.0, is_float=False), _LINEAR),
        (LinearConversion(scale=10.0, offset=1.0, is_float=True), _LINEAR),
        (
            NamedSignalConversion(scale=0.5, offset=1, choices=OrderedDict({0: "off"}), is_float=False),
            _LINEAR,
        ),
        (
            NamedSignalConversion(scale=1, offset=0, choices=OrderedDict({0: "off"}), is_float=False),
            _IDENTITY,
        ),
    ],
    ids=repr,
)
def test_the_conversion_arithmetic_is_what_the_layout_writes_out(conv: BaseConversion, kind: int) -> None:
    """``numeric_scaled_to_raw`` and ``raw_to_scaled(raw, False)`` of cantools, value for value
    (type and sign of zero included), against the layout's expressions for the same class."""
    assert _conversion(conv) == (kind, conv.scale, conv.offset)
    to_raw = _layout_to_raw(kind, conv.is_float, conv.scale, conv.offset)
    for v in _VALUES:
        ours, theirs = to_raw(v), conv.numeric_scaled_to_raw(v)
        assert (repr(ours), type(ours)) == (repr(theirs), type(theirs)), (v, ours, theirs)
        scaled = conv.raw_to_scaled(theirs, False)
        expected = theirs if kind == _IDENTITY else theirs * conv.scale + conv.offset
        assert repr(scaled) == repr(expected), (theirs, scaled)


def test_named_conversions_decode_choices_only_when_asked() -> None:
    conv = NamedSignalConversion(scale=1, offset=0, choices=OrderedDict({2: "ACTIVE"}), is_float=False)
    assert str(conv.raw_to_scaled(2)) == "ACTIVE"
    assert conv.raw_to_scaled(2, False) == 2
    assert conv.scaled_to_raw("ACTIVE") == 2


@pytest.mark.parametrize("dbc", [DEFAULT_DBC, VENDOR_DBC], ids=lambda p: p.name)
def test_every_message_of_the_shipped_dbcs_gets_the_fast_layout(dbc: Path) -> None:
    """Each signal's conversion is one of the classes above (a new class would make
    :meth:`BitLayout.of` return None and every frame take cantools' slow path)."""
    db = cantools.database.load_file(str(dbc))
    assert isinstance(db, cantools.database.can.Database)
    for msg in db.messages:
        assert all(_conversion(s.conversion) is not None for s in msg.signals), msg.name
        assert BitLayout.of(msg) is not None, msg.name


def test_python_can_s_socketcan_constants_are_linux_s() -> None:
    """``SOL_CAN_RAW`` and ``CAN_RAW_RECV_OWN_MSGS`` of <linux/can/raw.h> (SOL_CAN_BASE + CAN_RAW, 4)."""
    from can.interfaces.socketcan.constants import CAN_RAW_RECV_OWN_MSGS, SOL_CAN_RAW

    assert (SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS) == (101, 4)
