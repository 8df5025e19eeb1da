"""Protected volumes: the exact integer predicate against an independent rational distance
(and shapely), the circuit on plain bits against the predicate, and the private protocol
against the predicate -- random cases and the adversarial ones (parallels at r - 1, r, r + 1,
collinear gaps, tees stopping short, zero-length segments, touching windows and bands)."""

from __future__ import annotations

from fractions import Fraction
from typing import Any, cast

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString
from shapely.geometry import Point as ShapelyPoint

from protocol.circuits.boolean import Circuit
from protocol.circuits.paths import Capsules, Orient, Proj, Range, volume_hits
from protocol.compact.plan import message_sizes
from protocol.errors import InputRangeError
from protocol.geo.geometry import Point, orient, path_hits, projection_key, segments_intersect
from protocol.geo.grid import GridKind, GridSpec
from protocol.geo.volumes import (
    NO_SEPARATION,
    Interval,
    Route,
    Separation,
    VolumeSpec,
    bands_near,
    point_near_segment,
    route_hits,
    segments_near,
    slab_radius,
    windows_meet,
)
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.run import Limits, Wires
from protocol.tools.loopback import run_paths

# --------------------------------------------------------------------------- the predicate


def _dist2_point(x: Point, u: Point, v: Point) -> Fraction:
    """Squared distance from x to the closed segment [u, v], exactly (rationals)."""
    dx, dy = v[0] - u[0], v[1] - u[1]
    length = dx * dx + dy * dy
    if length == 0:
        return Fraction((x[0] - u[0]) ** 2 + (x[1] - u[1]) ** 2)
    t = Fraction((x[0] - u[0]) * dx + (x[1] - u[1]) * dy, length)
    t = min(Fraction(1), max(Fraction(0), t))
    px, py = u[0] + t * dx, u[1] + t * dy
    return (x[0] - px) ** 2 + (x[1] - py) ** 2


def exact_dist2(a: Point, b: Point, c: Point, d: Point) -> Fraction:
    """The oracle: squared distance of two closed segments (0 when they meet)."""
    if segments_intersect(a, b, c, d):
        return Fraction(0)
    return min(
        _dist2_point(c, a, b), _dist2_point(d, a, b), _dist2_point(a, c, d), _dist2_point(b, c, d)
    )


def points(bound: int) -> st.SearchStrategy[Point]:
    return st.tuples(st.integers(-bound, bound), st.integers(-bound, bound))


@settings(max_examples=3000, deadline=None)
@given(points(4), points(4), points(4), points(4), st.integers(0, 6))
def test_segments_near_is_the_exact_distance_on_a_tiny_grid(a, b, c, d, r) -> None:  # type: ignore[no-untyped-def]
    """A 9 x 9 grid: touching, collinear and zero-length cases are the common case."""
    assert segments_near(a, b, c, d, r) is (exact_dist2(a, b, c, d) <= r * r)
    assert segments_near(c, d, a, b, r) is segments_near(a, b, c, d, r)  # symmetric


@settings(max_examples=1500, deadline=None)
@given(points(2000), points(2000), points(2000), points(2000), st.integers(0, 400))
def test_segments_near_on_a_wide_grid(a, b, c, d, r) -> None:  # type: ignore[no-untyped-def]
    exact = exact_dist2(a, b, c, d)
    assert segments_near(a, b, c, d, r) is (exact <= r * r)
    shape1 = ShapelyPoint(a) if a == b else LineString([a, b])
    shape2 = ShapelyPoint(c) if c == d else LineString([c, d])
    assert abs(shape1.distance(shape2) ** 2 - float(exact)) <= 1e-6 * max(1.0, float(exact))


def test_with_no_separation_it_is_the_crossing() -> None:
    grid = [(x, y) for x in range(-2, 3) for y in range(-2, 3)]
    for a in grid[::3]:
        for b in grid[::2]:
            for c in grid[::3]:
                for d in grid[1::2]:
                    assert segments_near(a, b, c, d, 0) is segments_intersect(a, b, c, d)


def test_slab_radius_is_exact_and_empty_for_a_point() -> None:
    assert slab_radius((0, 0), (3, 4), 2) == 10  # sqrt(4 * 25)
    assert slab_radius((0, 0), (1, 1), 1) == 1  # floor(sqrt(2))
    assert slab_radius((5, 5), (5, 5), 9) == -1
    assert point_near_segment((5, 6), (5, 5), (5, 5), 1) and not point_near_segment(
        (5, 7), (5, 5), (5, 5), 1
    )


def test_bands_and_windows_touching_count() -> None:
    assert bands_near((0, 10), (20, 30), 10) and not bands_near((0, 10), (21, 30), 10)
    assert bands_near((20, 30), (0, 10), 10) and not bands_near((21, 30), (0, 10), 10)
    assert windows_meet((0, 5), (5, 9)) and not windows_meet((0, 5), (6, 9))
    assert bands_near(None, (0, 1), 0) and windows_meet((0, 1), None)


@settings(max_examples=200, deadline=None)
@given(st.lists(points(3), min_size=2, max_size=5), st.lists(points(3), min_size=2, max_size=5))
def test_route_hits_without_volumes_is_path_hits(alice: Any, bob: Any) -> None:
    assert route_hits(Route(tuple(alice)), Route(tuple(bob)), Separation()) == path_hits(alice, bob)


# --------------------------------------------------------------------------- the circuit


def _plain_capsule_circuit(a: Point, b: Point, c: Point, d: Point, r: int, span: int) -> int:
    """The capsule circuit of one pair (m = n = 1) on plain comparison bits."""
    circuit = Circuit()

    def bit(value: bool) -> int:
        wire = circuit.input()
        inputs.append(int(value))
        return wire

    inputs: list[int] = []

    def orient_wires(o: int) -> Orient:
        return Orient(bit(o > 0), bit(o == 0))

    alice, bob = (a, b), (c, d)
    o1 = [[orient_wires(orient(a, b, p)) for p in bob]]
    ex, ey, off, t_max = projection_key(a, b, span)
    proj = [
        [
            Proj(bit(ex * p[0] + ey * p[1] + off < 0), bit(ex * p[0] + ey * p[1] + off > t_max))
            for p in bob
        ]
    ]
    o3 = [[orient_wires(orient(c, d, p))] for p in alice]
    radius_a, radius_b = slab_radius(a, b, r), slab_radius(c, d, r)
    length_b = (d[0] - c[0]) ** 2 + (d[1] - c[1]) ** 2
    near1 = [
        [Range(bit(orient(a, b, p) >= -radius_a), bit(orient(a, b, p) <= radius_a)) for p in bob]
    ]
    near3 = [
        [Range(bit(orient(c, d, p) >= -radius_b), bit(orient(c, d, p) <= radius_b))] for p in alice
    ]
    along = [((p[0] - c[0]) * (d[0] - c[0]) + (p[1] - c[1]) * (d[1] - c[1])) for p in alice]
    along3 = [[Range(bit(t >= 0), bit(t <= length_b))] for t in along]
    disc = [[bit((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 <= r * r) for q in bob] for p in alice]
    (hit,) = volume_hits(circuit, 1, 1, o1, proj, o3, capsules=Capsules(near1, near3, along3, disc))
    circuit.output(hit)
    return circuit.evaluate(inputs)[0]


@settings(max_examples=3000, deadline=None)
@given(points(4), points(4), points(4), points(4), st.integers(1, 6))
def test_capsule_circuit_is_the_predicate(a, b, c, d, r) -> None:  # type: ignore[no-untyped-def]
    assert _plain_capsule_circuit(a, b, c, d, r, 8) == int(segments_near(a, b, c, d, r))


def test_layout_positions_cover_every_form_once() -> None:
    from protocol.run import Kind, Layout

    layout = Layout(3, 2, capsules=True, bands=True, windows=True)
    positions = [layout.position(kind, row, col) for kind, row, col in layout.values]
    assert positions == list(range(len(layout.values)))
    assert {kind for kind, _, _ in layout.values} == set(Kind)
    assert len(layout.pairs()) == 6
    assert Wires() == Wires(None, None, None, None)


# --------------------------------------------------------------------------- the protocol

GRID = GridSpec(GridKind.PLANE, 120)
SPEC = VolumeSpec(Separation(0, 0), z_range=400, t_range=1000, epoch_s=1_790_000_000)


def run_volumes(
    alice: Route,
    bob: Route,
    ot_pair: Any,
    *,
    alice_sep: Separation = NO_SEPARATION,
    bob_sep: Separation = NO_SEPARATION,
    spec: VolumeSpec = SPEC,
    grid: GridSpec = GRID,
) -> tuple[list[bool], Any]:
    volumes = VolumeSpec(alice_sep, spec.z_range, spec.t_range, spec.epoch_s)
    a = Alice(alice, grid, setup=ot_pair.holder, volumes=volumes)
    b = Bob(bob, setups=ot_pair.setups, separation=bob_sep)
    transcript = run_paths(a, b)
    return a.hits, transcript


def _expect(
    alice: Route, bob: Route, separation: Separation, spec: VolumeSpec = SPEC
) -> list[bool]:
    """The reference on the routes as the run sees them (bands and windows clamped)."""

    def clamp(route: Route) -> Route:
        bands = None if route.bands is None else tuple(spec.clamp_band(x) for x in route.bands)
        windows = (
            None if route.windows is None else tuple(spec.clamp_window(x) for x in route.windows)
        )
        return Route(route.points, bands, windows)

    return route_hits(clamp(alice), clamp(bob), separation)


R = 10
# (name, Alice's route, Bob's route, the answer the case is built to have)
ADVERSARIAL: list[tuple[str, Route, Route, list[bool]]] = [
    ("parallel at r - 1", Route(((0, 0), (40, 0))), Route(((40, R - 1), (0, R - 1))), [True]),
    ("parallel at r", Route(((0, 0), (40, 0))), Route(((40, R), (0, R))), [True]),
    ("parallel at r + 1", Route(((0, 0), (40, 0))), Route(((40, R + 1), (0, R + 1))), [False]),
    ("collinear gap r", Route(((0, 0), (20, 0))), Route(((20 + R, 0), (60, 0))), [True]),
    ("collinear gap r + 1", Route(((0, 0), (20, 0))), Route(((21 + R, 0), (60, 0))), [False]),
    ("tee stopping r short", Route(((0, 0), (40, 0))), Route(((20, 40), (20, R))), [True]),
    ("tee stopping r + 1 short", Route(((0, 0), (40, 0))), Route(((20, 40), (20, R + 1))), [False]),
    ("beyond the end, diagonal r", Route(((0, 0), (40, 0))), Route(((46, 8), (60, 30))), [True]),
    ("beyond the end, just over", Route(((0, 0), (40, 0))), Route(((47, 8), (60, 30))), [False]),
    (
        "crossing in the middles",
        Route(((-40, -40), (40, 40))),
        Route(((-40, 40), (40, -40))),
        [True],
    ),
    ("Alice zero-length at r", Route(((5, R), (5, R))), Route(((0, 0), (30, 0))), [True]),
    (
        "Alice zero-length at r + 1",
        Route(((5, R + 1), (5, R + 1))),
        Route(((0, 0), (30, 0))),
        [False],
    ),
    ("Bob zero-length at r", Route(((0, 0), (30, 0))), Route(((35, 6), (35, 6))), [True]),
    (
        "both zero-length at r + 1",
        Route(((0, 0), (0, 0))),
        Route(((R + 1, 0), (R + 1, 0))),
        [False],
    ),
    (
        "bands within v",
        Route(((0, 0), (40, 0)), bands=((100, 110),)),
        Route(((0, 5), (40, 5)), bands=((120, 130),)),
        [True],
    ),
    (
        "bands v + 1 apart",
        Route(((0, 0), (40, 0)), bands=((100, 110),)),
        Route(((0, 5), (40, 5)), bands=((121, 130),)),
        [False],
    ),
    (
        "bands below, touching v",
        Route(((0, 0), (40, 0)), bands=((100, 110),)),
        Route(((0, 5), (40, 5)), bands=((60, 90),)),
        [True],
    ),
    (
        "windows touching",
        Route(((0, 0), (40, 0)), windows=((10, 50),)),
        Route(((0, 5), (40, 5)), windows=((50, 80),)),
        [True],
    ),
    (
        "windows one second apart",
        Route(((0, 0), (40, 0)), windows=((10, 50),)),
        Route(((0, 5), (40, 5)), windows=((51, 80),)),
        [False],
    ),
    (
        "near in space, two segments, one in time",
        Route(((0, 0), (40, 0), (40, 40)), bands=((0, 0), (0, 0)), windows=((0, 30), (30, 60))),
        Route(((45, 0), (45, 40)), bands=((0, 0),), windows=((0, 20),)),
        [True, False],
    ),
]


@pytest.mark.parametrize(
    ("name", "alice", "bob", "built"), ADVERSARIAL, ids=[c[0] for c in ADVERSARIAL]
)
def test_adversarial_volumes(
    name: str, alice: Route, bob: Route, built: list[bool], ot_pair: Any
) -> None:
    separation = Separation(R, 10)
    hits, _ = run_volumes(alice, bob, ot_pair, alice_sep=separation)
    assert _expect(alice, bob, separation) == built  # the case is what it says it is
    assert hits == built


def routes(max_segments: int, bound: int) -> st.SearchStrategy[Route]:
    @st.composite
    def build(draw: st.DrawFn) -> Route:
        pts = draw(st.lists(points(bound), min_size=2, max_size=max_segments + 1))
        count = len(pts) - 1
        interval = st.tuples(st.integers(-30, 450), st.integers(0, 60)).map(
            lambda x: (x[0], x[0] + x[1])
        )
        bands = draw(st.none() | st.lists(interval, min_size=count, max_size=count))
        windows = draw(st.none() | st.lists(interval, min_size=count, max_size=count))
        # the lists are never empty (count >= 1): ``x and tuple(x)`` is a tuple or None
        return Route(
            tuple(pts),
            cast(tuple[Interval, ...] | None, bands and tuple(bands)),
            cast(tuple[Interval, ...] | None, windows and tuple(windows)),
        )

    return build()


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    alice=routes(4, 12),
    bob=routes(4, 12),
    r_a=st.integers(0, 6),
    r_b=st.integers(0, 6),
    v=st.integers(0, 40),
)
def test_random_volumes_agree_with_the_predicate(
    alice: Route, bob: Route, r_a: int, r_b: int, v: int, ot_pair: Any
) -> None:
    """Small grids make near, touching and degenerate cases common; each party brings its own
    separation and the run uses the larger."""
    grid = GridSpec(GridKind.PLANE, 20)
    hits, _ = run_volumes(
        alice, bob, ot_pair, alice_sep=Separation(r_a, v), bob_sep=Separation(r_b, 0), grid=grid
    )
    assert hits == _expect(alice, bob, Separation(max(r_a, r_b), v))


@pytest.mark.slow
@settings(
    max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(alice=routes(6, 2000), bob=routes(6, 2000), r=st.integers(1, 300))
def test_wide_volumes_agree_with_the_predicate(
    alice: Route, bob: Route, r: int, ot_pair: Any
) -> None:
    grid = GridSpec(GridKind.PLANE, 2400)
    hits, _ = run_volumes(alice, bob, ot_pair, alice_sep=Separation(r, 20), grid=grid)
    assert hits == _expect(alice, bob, Separation(r, 20))


def test_sizes_are_known_before_the_run(ot_pair: Any) -> None:
    alice = Route(((0, 0), (40, 0), (40, 40)), bands=((0, 4), (4, 9)), windows=((0, 9), (9, 20)))
    bob = Route(((45, 0), (45, 40)))
    volumes = VolumeSpec(Separation(7, 3), SPEC.z_range, SPEC.t_range, SPEC.epoch_s)
    a = Alice(alice, GRID, setup=ot_pair.holder, volumes=volumes)
    b = Bob(bob, setups=ot_pair.setups, separation=Separation(9, 0))
    t = run_paths(a, b)
    run = VolumeSpec(Separation(9, 3), SPEC.z_range, SPEC.t_range, SPEC.epoch_s)
    expected = message_sizes(2, 1, GRID, volumes=run)
    assert [size for _, size in expected] == [size for _, size in t.sizes]


def test_a_box_without_room_for_the_separation_is_refused(ot_pair: Any) -> None:
    """Bob's path is cut to the box: the box must hold everything within r of Alice's."""
    grid = GridSpec(GridKind.PLANE, 50)
    alice = Route(((0, 0), (45, 0)))
    a = Alice(alice, grid, setup=ot_pair.holder, volumes=VolumeSpec(Separation(4, 0)))
    b = Bob(((0, 10), (40, 10)), setups=ot_pair.setups, separation=Separation(5, 0))
    with pytest.raises(InputRangeError, match="separation 5 needs 6 grid units"):
        run_paths(a, b)


def test_a_peer_asking_for_a_huge_separation_is_refused(ot_pair: Any) -> None:
    from protocol.errors import RemoteProtocolError

    a = Alice(((0, 0), (5, 0)), GRID, setup=ot_pair.holder, limits=Limits(max_separation=20))
    b = Bob(((0, 1), (5, 1)), setups=ot_pair.setups, separation=Separation(21, 0))
    with pytest.raises(RemoteProtocolError, match="separation of 21"):
        run_paths(a, b)


def test_the_paper_suite_keeps_the_papers_predicate(keys: Any) -> None:
    with pytest.raises(InputRangeError, match="paper's predicate"):
        Alice(((0, 0), (1, 1)), GRID, suite=Suite.PAPER, volumes=SPEC, trusted_keys=True)


def test_crossing_runs_are_unchanged_by_default(ot_pair: Any) -> None:
    """No separation, altitudes or times: the run is the paper's crossing test, same size."""
    _, plain = run_volumes(
        Route(((0, 0), (9, 9))), Route(((0, 9), (9, 0))), ot_pair, spec=VolumeSpec()
    )
    assert [size for _, size in plain.sizes] == [size for _, size in message_sizes(1, 1, GRID)]
