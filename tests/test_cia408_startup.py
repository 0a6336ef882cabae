"""The master's start-up (issue #18 item 3, first steps) against the emulated nodes: identities
checked by SDO, NMT start confirmed in the heartbeat; a missing node or one of another profile
is one NodeError line naming it."""

from __future__ import annotations

import pytest
from _cia408 import Cia408Rig, wait_until

from ehpss_hil.errors import NodeError
from ehpss_hil.protocol.cia408.objects import PROFILE_VALVE, NmtState
from ehpss_hil.protocol.cia408.startup import STARTUP_HEARTBEAT_MS, check_identity, start_nodes, stop_nodes


def _rig(name: str) -> Cia408Rig:
    return Cia408Rig({"interface": "virtual", "receive_own_messages": False, "channel": f"startup-{name}"})


def test_start_up_checks_identities_and_starts_both_nodes() -> None:
    with _rig("ok") as r:
        valve, encoder = start_nodes(r.valve, r.encoder)
        assert (valve.node_id, valve.profile, valve.product_code) == (32, 408, 0x408)
        assert (encoder.node_id, encoder.profile, encoder.device_type) == (33, 406, 0x80196)
        assert valve.text().startswith("node 32: CiA 408 (device type 0x00000198), vendor 0x00000EE5")
        assert r.proc.valve.nmt == NmtState.OPERATIONAL and r.proc.encoder.nmt == NmtState.OPERATIONAL
        assert r.proc.valve.store.get(0x1017) == STARTUP_HEARTBEAT_MS
        stop_nodes(r.valve, r.encoder)
        assert wait_until(lambda: r.proc.valve.nmt == r.proc.encoder.nmt == NmtState.STOPPED)


def test_a_node_of_another_profile_is_refused() -> None:
    with _rig("swap") as r:
        with pytest.raises(NodeError) as exc:
            check_identity(r.encoder, PROFILE_VALVE, "valve")  # the encoder where the valve should be
        assert str(exc.value) == "valve node 33: device type 0x00080196 is CiA 406, expected CiA 408"
        assert exc.value.exit_code == 3


def test_a_missing_node_is_refused_naming_it() -> None:
    with _rig("missing") as r:
        ghost = r.net.add_node(40, r.valve.object_dictionary)
        with pytest.raises(NodeError, match=r"^valve node 40: SDO read of 0x1000 failed: "):
            check_identity(ghost, PROFILE_VALVE, "valve")
