"""The path protocol agrees with the plaintext predicate (shapely-checked), on both suites."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.errors import InputRangeError, LocalProtocolError, RemoteProtocolError
from protocol.geo.geometry import Point, pad_path, path_hits
from protocol.geo.grid import GridKind, GridSpec
from protocol.intersection import Alice, Bob
from protocol.messages import Hello, Suite
from protocol.run import Limits, State
from protocol.tools.loopback import run_paths
from protocol.tools.paper_data import load_paper_data
from tests.paper_shaped import PaperShaped
from tests.protocol.adversarial import ADVERSARIAL, R
from tests.protocol.paths import GRID, machines, run


@pytest.mark.parametrize(("name", "pair"), ADVERSARIAL, ids=[n for n, _ in ADVERSARIAL])
def test_adversarial_pairs_compact(name: str, pair: Any, ot_pair: Any) -> None:
    a, b, c, d = pair
    hits, _transcript = run(
        (a, b), (c, d), Suite.COMPACT, None, ot_pair, GridSpec(GridKind.PLANE, R)
    )
    assert hits == path_hits((a, b), (c, d))


@pytest.mark.parametrize("index", [0, 2, 14, 16, 20, 29])
def test_adversarial_pairs_paper_suite(index: int, keys: Any) -> None:
    a, b, c, d = ADVERSARIAL[index][1]
    hits, _ = run((a, b), (c, d), Suite.PAPER, keys, None)
    assert hits == path_hits((a, b), (c, d))


def small_paths(max_segments: int) -> st.SearchStrategy[tuple[Point, ...]]:
    point = st.tuples(st.integers(-3, 3), st.integers(-3, 3))
    return st.lists(point, min_size=2, max_size=max_segments + 1).map(tuple)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(alice_path=small_paths(4), bob_path=small_paths(4))
def test_random_degenerate_paths_compact(alice_path: Any, bob_path: Any, ot_pair: Any) -> None:
    """Paths on a 7 x 7 grid: shared vertices, overlaps and zero-length segments abound."""
    hits, _ = run(alice_path, bob_path, Suite.COMPACT, None, ot_pair, GridSpec(GridKind.PLANE, 3))
    assert hits == path_hits(alice_path, bob_path)


@pytest.mark.slow
@settings(
    max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(alice_path=small_paths(2), bob_path=small_paths(2))
def test_random_degenerate_paths_paper(alice_path: Any, bob_path: Any, keys: Any) -> None:
    hits, _ = run(alice_path, bob_path, Suite.PAPER, keys, None, GridSpec(GridKind.PLANE, 3))
    assert hits == path_hits(alice_path, bob_path)


@settings(
    max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_random_wide_paths_compact(data: st.DataObject, ot_pair: Any) -> None:
    """Longer paths over a large range (l = 34): the full comparison width is exercised."""
    r = data.draw(st.sampled_from([1, 2000, 30000]))
    point = st.tuples(st.integers(-r, r), st.integers(-r, r))
    alice_path = tuple(data.draw(st.lists(point, min_size=2, max_size=7)))
    bob_path = tuple(data.draw(st.lists(point, min_size=2, max_size=7)))
    hits, _ = run(alice_path, bob_path, Suite.COMPACT, None, ot_pair, GridSpec(GridKind.PLANE, r))
    assert hits == path_hits(alice_path, bob_path)


def test_paper_suite_multi_segment(keys: Any) -> None:
    hits, _ = run(
        ((0, 0), (10, 0), (10, 10)), ((5, -5), (5, 5), (20, 5), (20, 20)), Suite.PAPER, keys, None
    )
    assert hits == [True, True]


def test_benchmark_pairs(benchmark_data: PaperShaped, ot_pair: Any) -> None:
    """The 30 single-segment pairs (the paper's, or the project's of the same shape), read as
    ``bench paper`` reads them, against their answers."""
    pairs = load_paper_data(benchmark_data.directory).pairs
    got = "".join(
        "1" if run(c.alice, c.bob, Suite.COMPACT, None, ot_pair, c.grid)[0][0] else "0"
        for c in pairs
    )
    assert got == benchmark_data.pair_bits


def test_benchmark_routes(benchmark_data: PaperShaped, ot_pair: Any) -> None:
    """The five route tests: Alice's segments that meet Bob's path, and testroutine.csv's
    "any intersection" per route."""
    routes = load_paper_data(benchmark_data.directory).routes
    assert [r.number for r in routes] == [1, 2, 3, 4, 5]
    for route in routes:
        c = route.case
        hits, _ = run(c.alice, c.bob, Suite.COMPACT, None, ot_pair, c.grid)
        expected = benchmark_data.route_hits[route.number]
        assert [i for i, h in enumerate(hits) if h] == expected, route.number
        assert route.expected_any is bool(expected)


def test_geographic_paths(ot_pair: Any) -> None:
    """Bob's waypoints in degE7, projected on Alice's grid after her hello."""
    lat, lon = 473_977_420, 85_455_940  # Zurich
    grid = GridSpec.geo(lat, lon, radius_m=2000)
    bob_geo = ((lat - 9_000, lon), (lat + 9_000, lon))  # ~200 m north-south line
    alice_geo = ((lat, lon - 13_000), (lat, lon + 13_000), (lat + 20_000, lon + 13_000))
    alice, bob = machines(
        grid.project_path(alice_geo), bob_geo, Suite.COMPACT, None, ot_pair, grid, geographic=True
    )
    run_paths(alice, bob)
    assert alice.hits == [True, False]


def test_bob_path_beyond_the_box_is_cut_not_refused(ot_pair: Any) -> None:
    """A grid that always fits: Bob's path far outside Alice's box is cut at its edge."""
    grid = GridSpec(GridKind.PLANE, 20)
    alice_path = ((-10, 0), (10, 0), (10, 10))
    bob_path = ((0, -5000), (0, 5000), (9000, 9000))  # crosses segment 0, leaves the box
    hits, _ = run(alice_path, bob_path, Suite.COMPACT, None, ot_pair, grid)
    assert hits == [True, False]
    far = ((5000, 5000), (6000, 5000))  # entirely outside: nothing to meet
    hits, _ = run(alice_path, far, Suite.COMPACT, None, ot_pair, grid)
    assert hits == [False, False]


@pytest.mark.parametrize("suite", [Suite.COMPACT, Suite.PAPER])
def test_where_bob_lies_changes_neither_the_replies_nor_a_refusal(
    suite: Suite, ot_pair: Any, keys: Any
) -> None:
    """The abort probe: Alice picks a box; inside it, leaving it and coming back, or far
    outside, Bob's replies have the same sizes (n is his own path's padded size), nothing is
    refused, and the answer stays safe: exact for the pieces, 'meets' everywhere when the
    pieces do not fit (the V below needs 3 segments, its public size is 2)."""
    grid = GridSpec(GridKind.PLANE, 20)
    alice_path = ((-15, 0), (15, 0), (15, 15))
    placements = {
        "inside": (((-5, -5), (0, 5), (5, -5)), [True, False]),
        "tip outside": (((-5, -5), (0, 500), (5, -5)), [True, True]),
        "far": (((500, 500), (600, 500), (700, 600)), [False, False]),
    }
    sizes = set()
    for bob_path, expected in placements.values():
        hits, transcript = run(alice_path, bob_path, suite, keys, ot_pair, grid)
        assert hits == expected
        sizes.add(tuple(transcript.sizes))
    assert len(sizes) == 1


@pytest.mark.parametrize("suite", [Suite.COMPACT, Suite.PAPER])
def test_a_size_asked_is_the_size_answered_whatever_bobs_path(
    suite: Suite, ot_pair: Any, keys: Any
) -> None:
    """``Hello.n``: Alice asks Bob for exactly four segments.  Whether his path has one,
    three or four, every message of the run has the same size (a listener reads nothing of
    his path from it) and the answer is the predicate's on his path; a Bob who answers
    another size is refused by name, and a path longer than asked is his own bug."""
    alice_path = ((0, 0), (10, 10), (20, 0))
    bobs = (
        ((0, 10), (10, 0)),
        ((0, 10), (10, 0), (15, 15), (25, 5)),
        tuple((k, 30) for k in range(5)),
    )
    sizes = set()
    for bob_path in bobs:
        alice = Alice(
            alice_path, GRID, suite=suite, setup=ot_pair.holder, ask_n=4, trusted_keys=True
        )
        bob = Bob(bob_path, keys=keys.bob, setups=ot_pair.setups)
        transcript = run_paths(alice, bob)
        assert alice.n == 4 and alice.hits == path_hits(alice_path, bob_path)
        sizes.add(tuple(transcript.sizes))
    assert len(sizes) == 1
    alice = Alice(alice_path, GRID, suite=suite, setup=ot_pair.holder, ask_n=2, trusted_keys=True)
    hello = alice.start()
    bob = Bob(bobs[0], keys=keys.bob, setups=ot_pair.setups)
    other = dataclasses.replace(Hello.from_bytes(hello), n=1).to_bytes()  # Bob reads 1
    with pytest.raises(RemoteProtocolError, match="2 were asked"):
        alice.receive(bob.receive(other) or b"")
    with pytest.raises(LocalProtocolError, match="3 segments where 2"):
        Bob(bobs[1], keys=keys.bob, setups=ot_pair.setups).receive(hello)
    with pytest.raises(InputRangeError):
        Alice(alice_path, GRID, suite=suite, ask_n=257, trusted_keys=True)


def test_message_sizes_depend_only_on_public_values(ot_pair: Any, keys: Any) -> None:
    for suite in (Suite.COMPACT, Suite.PAPER):
        _, crossing = run(((0, 0), (10, 10), (20, 0)), ((0, 10), (10, 0)), suite, keys, ot_pair)
        _, apart = run(
            ((50, 50), (51, 50), (52, 50)), ((-50, -50), (-60, -60)), suite, keys, ot_pair
        )
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


@pytest.mark.parametrize("kappa", [112, 128])
def test_cached_setup_is_reused_and_unknown_setups_are_refused(ot_pair: Any, kappa: int) -> None:
    fresh = Alice(((0, 0), (1, 1)), GRID, ot_security=kappa)
    assert len(fresh.start()) > 32 * kappa  # kappa base-OT points
    fresh = Alice(((0, 0), (1, 1)), GRID, ot_security=kappa)
    bob_setups: dict[bytes, Any] = {}
    run_paths(fresh, Bob(((0, 1), (1, 0)), setups=bob_setups))
    assert fresh.hits == [True]
    assert fresh.setup is not None and list(bob_setups) == [fresh.setup.setup_id]
    assert sum(fresh.setup.blocks) == kappa
    again = Alice(((0, 0), (1, 1)), GRID, setup=fresh.setup)
    assert len(again.start()) < 200  # the setup id instead of the points
    again = Alice(((0, 0), (1, 1)), GRID, setup=fresh.setup)
    run_paths(again, Bob(((0, 1), (1, 0)), setups=bob_setups))
    assert again.hits == [True]
    stranger = Alice(((0, 0), (1, 1)), GRID, setup=ot_pair.holder)
    bob = Bob(((0, 1), (1, 0)), setups=bob_setups)
    with pytest.raises(RemoteProtocolError, match="unknown OT setup"):
        bob.receive(stranger.start())
    assert bob.state is State.FAILED


# --------------------------------------------------------------------------- state machines


def test_out_of_order_and_failed_states(ot_pair: Any) -> None:
    alice = Alice(((0, 0), (1, 1)), GRID, setup=ot_pair.holder)
    with pytest.raises(LocalProtocolError):
        _ = alice.hits
    hello = alice.start()
    with pytest.raises(LocalProtocolError):
        alice.start()
    with pytest.raises(RemoteProtocolError):
        alice.receive(hello)  # a HELLO where the OFFER is expected
    assert alice.state is State.FAILED
    with pytest.raises(LocalProtocolError):
        alice.receive(hello)


def test_a_local_bug_is_not_the_peers_fault(ot_pair: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """An IndexError inside our own step stays an IndexError (a bug, exit 3 on the command line,
    "internal" in the companion's log), never a RemoteProtocolError that blames the peer; the
    machine still fails."""
    alice = Alice(((0, 0), (1, 1)), GRID, setup=ot_pair.holder)
    bob = Bob(((0, 1), (1, 0)), setups=ot_pair.setups)
    offer = bob.receive(alice.start())
    assert offer is not None

    def broken(data: bytes) -> bytes | None:
        raise IndexError("a bug of ours")

    monkeypatch.setattr(alice._impl, "_step", broken)
    with pytest.raises(IndexError, match="a bug of ours"):
        alice.receive(offer)
    assert alice.state is State.FAILED


def test_bob_refuses_weak_kappa_and_oversized_paths(keys: Any, ot_pair: Any) -> None:
    weak = Alice(
        ((0, 0), (1, 1)),
        GRID,
        suite=Suite.PAPER,
        kappa=20,
        trusted_keys=True,
        insecure_for_tests=True,
    )
    with pytest.raises(RemoteProtocolError, match="kappa"):
        Bob(((0, 1), (1, 0)), keys=keys.bob).receive(weak.start())
    long_path = tuple((i % 5, i % 7) for i in range(9))  # 8 segments
    alice = Alice(long_path, GRID, setup=ot_pair.holder)
    bob = Bob(((0, 1), (1, 0)), setups=ot_pair.setups, limits=Limits(max_segments=4))
    with pytest.raises(RemoteProtocolError, match="segments"):
        bob.receive(alice.start())
    assert bob.state is State.FAILED


def test_suite_choice(keys: Any) -> None:
    alice = Alice(((0, 0), (1, 1)), GRID, suite=Suite.PAPER, trusted_keys=True)
    with pytest.raises(RemoteProtocolError, match="suite"):
        Bob(((0, 1), (1, 0)), suites=(Suite.COMPACT,)).receive(alice.start())
    with pytest.raises(LocalProtocolError, match="keys"):
        Bob(((0, 1), (1, 0))).receive(
            Alice(((0, 0), (1, 1)), GRID, suite=Suite.PAPER, trusted_keys=True).start()
        )
    with pytest.raises(InputRangeError):
        Alice(((0, 0), (11, 0)), GridSpec(GridKind.PLANE, 10))


def test_oversized_peer_keys_are_refused(keys: Any) -> None:
    from protocol.messages import MsgType, frame, put_blob
    from protocol.paper.suite import read_dgk_key

    with pytest.raises(RemoteProtocolError, match="4096"):
        read_dgk_key(bytes([1]) * (3 * 1024 + 5), False)
    alice = Alice(((0, 0), (1, 1)), GRID, suite=Suite.PAPER, trusted_keys=True)
    alice.start()
    big_n = (1 << 8191) | 1  # odd, 8192 bits
    body = (1).to_bytes(2, "big") + put_blob(big_n.to_bytes(1024, "big")) + put_blob(b"")
    with pytest.raises(RemoteProtocolError):
        alice.receive(frame(MsgType.KEYS, 2, body))


@pytest.mark.parametrize(
    ("m", "n", "fresh"), [(1, 1, True), (2, 1, False), (4, 4, False), (3, 5, True)]
)
def test_message_sizes_are_known_before_the_run(m: int, n: int, fresh: bool, ot_pair: Any) -> None:
    from protocol.compact.plan import message_sizes

    grid = GridSpec(GridKind.PLANE, 2000)
    alice_path = tuple((i * 7, (i * 13) % 50) for i in range(m + 1))
    bob_path = tuple(((i * 11) % 40, i * 5) for i in range(n + 1))
    alice = Alice(alice_path, grid, setup=None if fresh else ot_pair.holder)
    bob = Bob(bob_path, setups={} if fresh else ot_pair.setups)
    assert alice.n is None  # Bob's size: unknown until his first reply
    transcript = run_paths(alice, bob)
    padded = Limits()
    assert alice.n == padded.padded(n)
    expected = message_sizes(padded.padded(m), padded.padded(n), grid, fresh_setup=fresh)
    assert [size for _, size in expected] == [size for _, size in transcript.sizes]
    again = message_sizes(padded.padded(m), padded.padded(n), grid, fresh_setup=fresh)
    assert again == expected and again is not expected  # cached, but the caller's own list
    assert [a for a, _ in expected] == [i % 2 == 0 for i in range(len(expected))]
