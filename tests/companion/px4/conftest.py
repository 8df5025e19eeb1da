"""PX4 SITL tests: the build comes from $PX4_SITL; without it they skip, with a bad one fail."""

from __future__ import annotations

import os

import pytest

from companion.sim.px4 import Px4Build, Px4Error, find_build

NO_BUILD = "PX4_SITL not set: PX4 SITL tests need a PX4 v1.16 SITL build (bin/px4, etc/)"


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Without PX4_SITL every ``px4`` test skips (a mark: -ra folds them into one line)."""
    if os.environ.get("PX4_SITL"):
        return
    for item in items:
        if item.get_closest_marker("px4") is not None:
            item.add_marker(pytest.mark.skip(reason=NO_BUILD))


@pytest.fixture(scope="session")
def px4_build() -> Px4Build:
    path = os.environ.get("PX4_SITL")
    if not path:
        pytest.skip(NO_BUILD)
    try:
        return find_build(path)
    except Px4Error as exc:
        pytest.fail(f"PX4_SITL={path} is not a usable PX4 SITL build: {exc}", pytrace=False)
