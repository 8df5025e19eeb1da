"""The encrypted path protocol agrees with the plaintext predicate, and its machines are strict."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.errors import InputRangeError, LocalProtocolError, RemoteProtocolError
from protocol.geometry import Point, path_hits
from protocol.grid import GridKind, GridSpec
from protocol.intersection import Alice, Bob, Limits, State, pad_path
from protocol.loopback import run_paths
from protocol.wire import Hello, Suite

from .adversarial import ADVERSARIAL, R

GRID = GridSpec(GridKind.PLANE, R)
DATA = Path(__file__).resolve().parents[3] / "shared" / "anchor-data"


def run(
    alice_path: tuple[Point, ...],
    bob_path: tuple[Point, ...],
    keys: Any,
    suite: Suite = Suite.COMPACT,
    grid: GridSpec = GRID,
) -> tuple[list[bool], Any]:
    alice = Alice(alice_path, grid, {suite: keys.alice[suite]})
    bob = Bob(bob_path, keys.bob)
    transcript = run_paths(alice, bob)
    assert alice.state is State.DONE and bob.state is State.DONE
    return alice.hits, transcript


@pytest.mark.parametrize(("name", "pair"), ADVERSARIAL, ids=[n for n, _ in ADVERSARIAL])
def test_adversarial_pairs_compact(name: str, pair: Any, path_keys: Any) -> None:
    a, b, c, d = pair
    hits, transcript = run((a, b), (c, d), path_keys)
    assert hits == path_hits((a, b), (c, d))
    assert transcript.messages == 8 and transcript.round_trips == 4


@pytest.mark.parametrize("index", [0, 2, 14, 16, 20, 29])
def test_adversarial_pairs_paper_suite(index: int, path_keys: Any) -> None:
    a, b, c, d = ADVERSARIAL[index][1]
    hits, _ = run((a, b), (c, d), path_keys, Suite.PAPER)
    assert hits == path_hits((a, b), (c, d))


def small_paths(max_segments: int) -> st.SearchStrategy[tuple[Point, ...]]:
    point = st.tuples(st.integers(-3, 3), st.integers(-3, 3))
    return st.lists(point, min_size=2, max_size=max_segments + 1).map(tuple)


@pytest.mark.slow
@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(alice_path=small_paths(4), bob_path=small_paths(3))
def test_random_degenerate_paths(alice_path: Any, bob_path: Any, path_keys: Any) -> None:
    """Paths on a 7 x 7 grid: shared vertices, overlaps and zero-length segments abound."""
    hits, _ = run(alice_path, bob_path, path_keys, grid=GridSpec(GridKind.PLANE, 3))
    assert hits == path_hits(alice_path, bob_path)


def test_paper_suite_multi_segment(path_keys: Any) -> None:
    alice_path = ((0, 0), (10, 0), (10, 10))
    bob_path = ((5, -5), (5, 5), (20, 5), (20, 20))
    hits, _ = run(alice_path, bob_path, path_keys, Suite.PAPER)
    assert hits == [True, True]


def _read(name: str) -> list[tuple[Point, ...]]:
    lines = (DATA / name).read_text().split()
    return [
        tuple((int(x), int(y)) for x, y in re.findall(r"\((-?\d+),(-?\d+)\)", ln)) for ln in lines
    ]


@pytest.mark.slow
def test_paper_benchmark_pairs(path_keys: Any) -> None:
    """The 30 pairs of the paper's benchmark against the answers in anchor-data/README.md."""
    expected = "110111000101101010000100000110"
    alice, bob = _read("alices_segments.txt"), _read("bobs_segments.txt")
    got = "".join(
        "1" if run(a, b, path_keys)[0][0] else "0" for a, b in zip(alice, bob, strict=True)
    )
    assert got == expected


@pytest.mark.slow
@pytest.mark.parametrize(
    ("route", "indices"), [(1, [0, 3]), (2, [0, 2]), (3, [0, 1, 2]), (4, []), (5, [1, 2, 3])]
)
def test_paper_routes(route: int, indices: list[int], path_keys: Any) -> None:
    alice, bob = _read(f"ownroute{route}.txt")[0], _read(f"cryptroute{route}.txt")[0]
    grid = GridSpec(GridKind.PLANE, 1500)
    hits, _ = run(alice, bob, path_keys, grid=grid)
    assert [i for i, h in enumerate(hits) if h] == indices


def test_geographic_paths(path_keys: Any) -> None:
    """Bob's waypoints in degE7, projected on Alice's grid after her hello."""
    lat, lon = 473_977_420, 85_455_940  # Zurich
    grid = GridSpec.geo(lat, lon, radius_m=2000)
    bob_geo = ((lat - 9_000, lon), (lat + 9_000, lon))  # ~200 m north-south line
    alice_geo = ((lat, lon - 13_000), (lat, lon + 13_000), (lat + 20_000, lon + 13_000))
    alice_path = grid.project_path(alice_geo)
    alice = Alice(alice_path, grid, {Suite.COMPACT: path_keys.alice[Suite.COMPACT]})
    bob = Bob(bob_geo, path_keys.bob, geographic=True)
    run_paths(alice, bob)
    assert alice.hits == [True, False]


def test_message_sizes_depend_only_on_public_values(path_keys: Any) -> None:
    _, crossing = run(((0, 0), (10, 10), (20, 0)), ((0, 10), (10, 0)), path_keys)
    _, apart = run(((50, 50), (51, 50), (52, 50)), ((-50, -50), (-60, -60)), path_keys)
    assert crossing.sizes == apart.sizes


def test_padding_changes_no_answer() -> None:
    path = ((0, 0), (3, 3), (6, 0))
    padded = pad_path(path, 4)
    assert padded == path + ((6, 0),) * 2
    bob = ((0, 3), (6, 3), (6, 6))
    assert path_hits(padded, bob)[:2] == path_hits(path, bob)
    assert path_hits(path, pad_path(bob, 8)) == path_hits(path, bob)


def test_limits() -> None:
    assert [Limits().padded(k) for k in (1, 2, 3, 5, 17, 256)] == [1, 2, 4, 8, 32, 256]
    assert Limits(pad_to_power_of_two=False).padded(5) == 5
    with pytest.raises(InputRangeError):
        Limits().padded(257)
    with pytest.raises(InputRangeError):
        Limits(max_segments=4).padded(5)


# --------------------------------------------------------------------------- state machines


def test_out_of_order_and_failed_states(path_keys: Any) -> None:
    alice = Alice(((0, 0), (1, 1)), GRID, {Suite.COMPACT: path_keys.alice[Suite.COMPACT]})
    with pytest.raises(LocalProtocolError):
        _ = alice.hits
    hello = alice.start()
    with pytest.raises(LocalProtocolError):
        alice.start()
    with pytest.raises(RemoteProtocolError):
        alice.receive(hello)  # a HELLO where KEYS is expected
    assert alice.state is State.FAILED
    with pytest.raises(LocalProtocolError):
        alice.receive(hello)


def test_bob_refuses_weak_kappa_and_oversized_paths(path_keys: Any) -> None:
    key = path_keys.alice[Suite.COMPACT]
    weak = Alice(((0, 0), (1, 1)), GRID, {Suite.COMPACT: key}, kappa=20, insecure_for_tests=True)
    with pytest.raises(RemoteProtocolError, match="kappa"):
        Bob(((0, 1), (1, 0)), path_keys.bob).receive(weak.start())
    long_path = tuple((i % 5, i % 7) for i in range(9))  # 8 segments
    alice = Alice(long_path, GRID, {Suite.COMPACT: key})
    bob = Bob(((0, 1), (1, 0)), path_keys.bob, limits=Limits(max_segments=4))
    with pytest.raises(RemoteProtocolError, match="segments"):
        bob.receive(alice.start())
    assert bob.state is State.FAILED


def test_suite_negotiation(path_keys: Any) -> None:
    from protocol.intersection import BobKeys

    alice = Alice(((0, 0), (1, 1)), GRID, {Suite.PAPER: path_keys.alice[Suite.PAPER]})
    compact_only = BobKeys(
        path_keys.bob.paillier, {Suite.COMPACT: path_keys.bob.bits[Suite.COMPACT]}
    )
    with pytest.raises(RemoteProtocolError, match="suite"):
        Bob(((0, 1), (1, 0)), compact_only).receive(alice.start())
    hello = Hello.from_bytes(Alice(((0, 0), (1, 1)), GRID, dict(path_keys.alice)).start())
    assert hello.suites == (Suite.COMPACT, Suite.PAPER)


def test_bob_path_outside_alices_grid(path_keys: Any) -> None:
    alice = Alice(
        ((0, 0), (1, 1)),
        GridSpec(GridKind.PLANE, 10),
        {Suite.COMPACT: path_keys.alice[Suite.COMPACT]},
    )
    with pytest.raises(RemoteProtocolError, match="grid"):
        Bob(((0, 0), (50, 50)), path_keys.bob).receive(alice.start())
    with pytest.raises(InputRangeError):
        Alice(((0, 0), (11, 0)), GridSpec(GridKind.PLANE, 10), dict(path_keys.alice))


def test_oversized_peer_keys_are_refused(path_keys: Any) -> None:
    from protocol.intersection import read_bits_key

    with pytest.raises(RemoteProtocolError, match="4096"):
        read_bits_key(Suite.PAPER, bytes([1]) * (3 * 1024 + 4))
    alice = Alice(((0, 0), (1, 1)), GRID, {Suite.COMPACT: path_keys.alice[Suite.COMPACT]})
    alice.start()
    from protocol.wire import KeysHeader, MsgType, frame

    big_n = (1 << 8191) | 1  # odd, 8192 bits
    head = KeysHeader(
        Suite.COMPACT,
        1,
        big_n.to_bytes(1024, "big"),
        path_keys.bob.bits[Suite.COMPACT].public_key.to_bytes(),
    )
    with pytest.raises(RemoteProtocolError):
        alice.receive(frame(MsgType.KEYS, head.to_bytes()))
