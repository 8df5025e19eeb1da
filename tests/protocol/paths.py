"""Running both parties of the path protocol in tests."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from protocol.geo.geometry import Point
from protocol.geo.grid import GridKind, GridSpec
from protocol.geo.volumes import Route
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.run import Limits, State
from protocol.tools.loopback import Transcript, run_paths

GRID = GridSpec(GridKind.PLANE, 99)


def machines(
    alice_path: Any,
    bob_path: Any,
    suite: Suite,
    keys: Any,
    ot_pair: Any,
    grid: GridSpec = GRID,
    limits: Limits | None = None,
    geographic: bool = False,
) -> tuple[Alice, Bob]:
    limits = limits or Limits()
    alice = Alice(
        alice_path,
        grid,
        suite=suite,
        setup=ot_pair.holder if ot_pair else None,
        limits=limits,
        trusted_keys=True,
    )
    bob = Bob(
        bob_path,
        keys=keys.bob if keys else None,
        setups=ot_pair.setups if ot_pair else {},
        geographic=geographic,
        limits=limits,
    )
    return alice, bob


def run(
    alice_path: Sequence[Point] | Route,
    bob_path: Sequence[Point] | Route,
    suite: Suite,
    keys: Any,
    ot_pair: Any,
    grid: GridSpec = GRID,
) -> tuple[list[bool], Transcript]:
    alice, bob = machines(alice_path, bob_path, suite, keys, ot_pair, grid)
    transcript = run_paths(alice, bob)
    assert alice.state is State.DONE and bob.state is State.DONE
    return alice.hits, transcript
