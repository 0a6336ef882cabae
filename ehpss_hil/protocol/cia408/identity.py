"""A node's 0x1018 identity against the config's ``cia408.valve_identity``/``encoder_identity``.

The master reads 0x1018.1–4 of each node at start-up (:mod:`.startup`); with an expected
vendor, product or revision in the config, a node that says otherwise is not the valve (or
encoder) the controller was set up for, and the start-up stops with one line naming the node,
the entry and both values (a :class:`~ehpss_hil.errors.NodeError`, exit 3). The emulator takes
the same keys as the identity it impersonates (:func:`identity_overrides`).
"""

from __future__ import annotations

from ...config import Cia408Config
from ...errors import NodeError
from ...profile_config import NodeIdentityConfig
from .objects import IDENTITY
from .startup import NodeIdentity

#: 0x1018 sub-index of each checked entry
IDENTITY_SUBS = {"vendor_id": 1, "product_code": 2, "revision": 3}


def check_expected(ident: NodeIdentity, expected: NodeIdentityConfig, role: str) -> None:
    """Each entry ``expected`` gives equals the node's, else a NodeError naming it."""
    for name, sub in IDENTITY_SUBS.items():
        want = getattr(expected, name)
        got = getattr(ident, name)
        if want is not None and got != want:
            raise NodeError(
                f"{role} node {ident.node_id}: 0x1018.{sub} {name} is 0x{got:08X}, the config "
                f"(cia408.{role}_identity.{name}) expects 0x{want:08X}"
            )


def expected_for(c: Cia408Config, role: str) -> NodeIdentityConfig:
    """The expected identity of the ``valve`` or the ``encoder`` of ``c``."""
    return c.valve_identity if role == "valve" else c.encoder_identity


def identity_overrides(expected: NodeIdentityConfig) -> dict[tuple[int, int], int]:
    """Power-on values of 0x1018 for an emulated node that impersonates ``expected``."""
    return {
        (IDENTITY, sub): getattr(expected, name)
        for name, sub in IDENTITY_SUBS.items()
        if getattr(expected, name) is not None
    }
