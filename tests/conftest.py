"""Suite-wide collection order: the tests marked ``slow`` first (stable otherwise), so that
``make test``'s pytest-xdist workers start them at once and the run does not end on one of them
alone."""

from __future__ import annotations

import pytest


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
