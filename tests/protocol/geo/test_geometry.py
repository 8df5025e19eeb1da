"""The circuit the protocol evaluates is exactly the closed-segment predicate (shapely oracle)."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString
from shapely.geometry import Point as ShapelyPoint

from protocol.geo.geometry import (
    circuit,
    circuit_with_line,
    fit_to_box,
    orient,
    orient_coefficients,
    path_hits,
    projection_key,
    segment_terms,
    segments_intersect,
)
from tests.protocol.adversarial import ADVERSARIAL, R


def shapely_intersects(a, b, c, d) -> bool:  # type: ignore[no-untyped-def]
    first = ShapelyPoint(a) if a == b else LineString([a, b])
    second = ShapelyPoint(c) if c == d else LineString([c, d])
    return bool(first.intersects(second))


@pytest.mark.parametrize(("name", "pair"), ADVERSARIAL, ids=[n for n, _ in ADVERSARIAL])
def test_adversarial_cases(name: str, pair) -> None:  # type: ignore[no-untyped-def]
    a, b, c, d = pair
    expected = shapely_intersects(a, b, c, d)
    assert segments_intersect(a, b, c, d) is expected
    assert circuit(a, b, c, d, 2 * R) == int(expected)
    # the predicate is symmetric; the circuit must be too
    assert circuit(c, d, a, b, 2 * R) == int(expected)


def points(bound: int) -> st.SearchStrategy[tuple[int, int]]:
    return st.tuples(st.integers(-bound, bound), st.integers(-bound, bound))


@settings(max_examples=3000, deadline=None)
@given(points(3), points(3), points(3), points(3))
def test_circuit_matches_shapely_on_a_tiny_grid(a, b, c, d) -> None:  # type: ignore[no-untyped-def]
    """A 7 x 7 grid makes collinear and touching cases the common case."""
    expected = shapely_intersects(a, b, c, d)
    assert segments_intersect(a, b, c, d) is expected
    assert circuit(a, b, c, d, 6) == int(expected)


@settings(max_examples=2000, deadline=None)
@given(points(R), points(R), points(R), points(R))
def test_circuit_matches_shapely_on_the_paper_range(a, b, c, d) -> None:  # type: ignore[no-untyped-def]
    expected = shapely_intersects(a, b, c, d)
    assert circuit(a, b, c, d, 2 * R) == int(expected)


@settings(max_examples=300, deadline=None)
@given(points(R), points(R), points(R), points(R))
def test_linear_forms(a, b, c, d) -> None:  # type: ignore[no-untyped-def]
    """The forms Alice evaluates on Bob's ciphertexts equal the plaintext values."""
    alpha, beta, gamma = orient_coefficients(a, b)
    assert alpha * c[0] + beta * c[1] + gamma == orient(a, b, c)
    dx, dy, k = segment_terms(c, d)
    assert a[1] * dx - a[0] * dy + k == orient(c, d, a)
    ex, ey, off, t = projection_key(a, b, 2 * R)
    bound = 8 * R * R
    assert abs(ex * c[0] + ey * c[1] + off) <= bound
    assert 0 <= t <= bound


def test_path_hits_on_the_paper_routes() -> None:
    alice = ((0, 0), (10, 0), (10, 10))
    bob = ((5, -5), (5, 5), (20, 5))
    assert path_hits(alice, bob) == [True, True]
    assert path_hits(alice, ((50, 50), (60, 60))) == [False, False]


# --------------------------------------------------------------------------- the public box


def _inside(points: Any, r: int) -> bool:
    return all(abs(x) <= r and abs(y) <= r for x, y in points)


@given(
    path=st.lists(st.tuples(st.integers(-400, 400), st.integers(-400, 400)), min_size=2, max_size=6)
)
def test_fit_stays_in_the_box_in_the_public_size_and_keeps_inside_paths(
    path: list[tuple[int, int]],
) -> None:
    r, n = 100, 8
    fitted = fit_to_box(path, r, n)
    assert fitted.segments == n and _inside(fitted.points, r)
    assert all(0 <= k < n for k in fitted.links)
    if _inside(path, r):
        assert fitted.points[: len(path)] == tuple(path) and not fitted.links
        assert not fitted.everywhere


@given(
    alice=st.lists(st.tuples(st.integers(-90, 90), st.integers(-90, 90)), min_size=2, max_size=4),
    bob=st.lists(st.integers(-400, 400), min_size=3, max_size=7),
)
def test_fit_is_exact_where_the_cut_falls_on_the_grid(
    alice: list[tuple[int, int]], bob: list[int]
) -> None:
    """An axis-parallel path (cut points are grid points) meets Alice's path inside the box
    exactly as before cutting: links between pieces never meet anything."""
    path = [(bob[0], bob[1])]
    for k, value in enumerate(bob[2:]):
        x, y = path[-1]
        path.append((value, y) if k % 2 == 0 else (x, value))
    n = len(path) - 1
    fitted = fit_to_box(path, 100, 2 * n)  # room for every link: never the fallback
    assert not fitted.everywhere
    assert fitted.hits(alice) == path_hits(alice, path)


@given(
    alice=st.lists(st.tuples(st.integers(-90, 90), st.integers(-90, 90)), min_size=2, max_size=4),
    path=st.lists(
        st.tuples(st.integers(-400, 400), st.integers(-400, 400)), min_size=2, max_size=6
    ),
    n=st.integers(1, 8),
)
def test_fit_never_misses_a_crossing(
    alice: list[tuple[int, int]], path: list[tuple[int, int]], n: int
) -> None:
    """Whatever the size: every crossing inside the box is answered (the cut points move at
    most half a cell, so allow a path that crosses within a cell of Alice's); a path that does
    not fit answers 'meets' everywhere."""
    fitted = fit_to_box(path, 100, n)
    got = fitted.hits(alice)
    if fitted.everywhere:
        assert all(got)
        return
    for i, hit in enumerate(path_hits(alice, path)):
        if hit and not got[i]:
            near = [
                (x + dx, y + dy)
                for x, y in alice[i : i + 2]
                for dx in (-1, 0, 1)
                for dy in (-1, 0, 1)
            ]
            assert any(path_hits([p, q], path)[0] for p in near for q in near if p != q)


def test_links_and_the_fallback_in_the_circuit() -> None:
    """The plain circuit on a link's line terms never meets; pieces joined by a link answer
    exactly; a path that does not fit answers everywhere."""
    from protocol.geo.geometry import DEAD_LINE

    a, b = (-5, 0), (5, 0)
    for c, d in (((0, -5), (0, 5)), ((-5, 0), (5, 0)), ((0, 0), (0, 0)), ((7, 0), (9, 0))):
        assert circuit_with_line(a, b, c, d, DEAD_LINE, 1000) == 0
    # a V leaving the box at its tip: two pieces and a link, n = 3
    v = [(-50, -50), (0, 500), (50, -50)]
    alice = [(-60, 0), (60, 0), (60, 1)]
    fitted = fit_to_box(v, 100, 3)
    assert fitted.links == frozenset({1}) and not fitted.everywhere
    assert fitted.hits(alice) == path_hits(alice, v) == [True, False]
    squeezed = fit_to_box(v, 100, 2)  # the public size of a two-segment path
    assert squeezed.everywhere and squeezed.hits(alice) == [True, True]
    assert fit_to_box([(500, 500), (600, 500)], 100, 2).hits(alice) == [False, False]


def test_fitting_to_the_box_costs_the_same_wherever_the_path_lies(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Bob fits his path to Alice's box before his first reply: the same clipping and
    rounding per segment whether it lies in the box or not (before, a segment outside
    skipped the rounding: 1.0 ms for a path outside, 4.5 ms inside, measured by a prober)."""
    from fractions import Fraction

    import protocol.geo.geometry as geometry

    calls: list[str] = []
    real_round, real_fraction = geometry._round_in, Fraction

    def counting_round(point: tuple[Fraction, Fraction], r: int) -> tuple[int, int]:
        calls.append("round")
        return real_round(point, r)

    def counting_fraction(*args: int) -> Fraction:
        calls.append("fraction")
        return real_fraction(*args)

    monkeypatch.setattr(geometry, "_round_in", counting_round)
    monkeypatch.setattr(geometry, "Fraction", counting_fraction)
    inside = [(-900 + 200 * k, (-1) ** k * 300) for k in range(9)]
    work = {}
    for name, path in (("inside", inside), ("outside", [(x + 5000, y) for x, y in inside])):
        calls.clear()
        geometry.fit_to_box(path, 1000, 8)
        work[name] = sorted(calls)
    assert work["inside"] == work["outside"] and work["inside"].count("round") == 16
