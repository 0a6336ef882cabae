"""Suite-wide: the collection order, and the share of the host each test takes.

Order: the tests marked ``slow`` first (stable otherwise), so that ``make test``'s pytest-xdist
workers start them at once and the run does not end on one of them alone.

Share: a test marked ``alone`` runs with no other test of any worker or suite on the host (it
judges a real-time loop by how many cycles it takes to react); every other test shares the host
(:func:`_host_share.host_share` on :data:`HOST_LOCK` and :data:`GATE_LOCK`). A share not had
within :data:`SHARE_WAIT_S` is a warning and the test runs anyway: the lock only makes the
real-time judgement likelier, it is never what a test asserts.
"""

from __future__ import annotations

import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
from _host_share import host_share

#: the lock file a test holds while it runs: shared, or exclusive for an ``alone`` test
HOST_LOCK = Path(tempfile.gettempdir()) / "ehpss-hil-tests-host.lock"
#: the lock file an ``alone`` test closes to the tests that have not started yet
GATE_LOCK = Path(tempfile.gettempdir()) / "ehpss-hil-tests-gate.lock"
#: how long a test waits for its share before it runs without it (s)
SHARE_WAIT_S = 900.0


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(autouse=True)
def _host_share(request: pytest.FixtureRequest) -> Iterator[None]:
    alone = request.node.get_closest_marker("alone") is not None
    with host_share(alone, HOST_LOCK, GATE_LOCK, SHARE_WAIT_S) as had:
        if not had:
            warnings.warn(
                f"ran without its share of the host (no lock in {SHARE_WAIT_S:.0f} s)", stacklevel=1
            )
        yield
