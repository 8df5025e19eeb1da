"""Data of the paper's shape, made by the project: the tests run every code path that reads the
paper's benchmark files (``protocol.tools.paper_data``) on a plain clone, where those files are
not (they are read from ``../shared/anchor-data`` when it is there, never carried).

Thirty single-segment pairs in +-99 and five route tests, in the paper's file layout, with
their answers from the plaintext predicate, each checked against shapely.  The pairs and routes
are random but built so that the cases the paper's data has (touching, collinear overlaps,
shared vertices, a route with no hit) and a zero-length segment are always among them.
"""

from __future__ import annotations

import random
from dataclasses import dataclass
from pathlib import Path

from shapely.geometry import LineString
from shapely.geometry import Point as ShapelyPoint

from protocol.geo.geometry import Point, path_hits

ANCHOR = Path(__file__).resolve().parents[2] / "shared" / "anchor-data"
# The answers the paper's own files have (anchor-data/README.md: closed segments, touching
# counts): the 30 pairs, line 1 first, and per route Alice's segments that meet Bob's path.
ANCHOR_PAIR_BITS = "110111000101101010000100000110"
ANCHOR_ROUTE_HITS = {1: [0, 3], 2: [0, 2], 3: [0, 1, 2], 4: [], 5: [1, 2, 3]}


@dataclass(frozen=True)
class PaperShaped:
    """A data directory and its answers."""

    directory: Path
    pair_bits: str  # "1" where pair k meets, line 1 first
    route_hits: dict[int, list[int]]  # per route: Alice's segments (0-based) that meet


def _shape(a: Point, b: Point) -> ShapelyPoint | LineString:
    return ShapelyPoint(a) if a == b else LineString([a, b])


def shapely_hits(alice: tuple[Point, ...], bob: tuple[Point, ...]) -> list[bool]:
    """The oracle: per segment of Alice, does it touch any segment of Bob (closed)?"""
    bobs = [_shape(bob[k], bob[k + 1]) for k in range(len(bob) - 1)]
    return [
        any(_shape(alice[i], alice[i + 1]).intersects(s) for s in bobs)
        for i in range(len(alice) - 1)
    ]


def _text(path: tuple[Point, ...]) -> str:
    return "".join(f"({x},{y})" for x, y in path)


def _point(rng: random.Random, r: int) -> Point:
    return rng.randint(-r, r), rng.randint(-r, r)


def _pairs(rng: random.Random) -> list[tuple[tuple[Point, ...], tuple[Point, ...]]]:
    pairs: list[tuple[tuple[Point, ...], tuple[Point, ...]]] = [
        ((_point(rng, 99), _point(rng, 99)), (_point(rng, 99), _point(rng, 99))) for _ in range(30)
    ]
    a, b = (-40, -20), (60, 30)  # on the line y = (x + 40) / 2
    pairs[0] = ((a, b), (b, (90, -50)))  # touching at an end point
    pairs[1] = ((a, b), ((0, 0), (80, 40)))  # collinear, overlapping
    pairs[2] = ((a, b), ((80, 40), (98, 49)))  # collinear, with a gap
    pairs[3] = (((20, 10), (20, 10)), ((20, -50), (20, 50)))  # Alice: a zero-length segment
    return pairs


def _routes(rng: random.Random) -> dict[int, tuple[tuple[Point, ...], tuple[Point, ...]]]:
    def walk(points: int, r: int = 1000) -> tuple[Point, ...]:
        return tuple(_point(rng, r) for _ in range(points))

    alice = walk(5)
    routes = {1: (alice, walk(5))}
    shared = walk(4)
    routes[2] = (shared, (_point(rng, 1000), shared[2], _point(rng, 1000)))  # a shared vertex
    (ax, ay), (bx, by) = alice[1], alice[2]
    beyond = (2 * bx - ax, 2 * by - ay)  # Bob runs along Alice's segment 1 and past it
    routes[3] = (alice, (alice[0], alice[1], beyond, _point(rng, 1000)))
    routes[4] = (alice, tuple((x + 2500, y) for x, y in walk(4)))  # far east: no hit
    stop = walk(3)
    routes[5] = ((stop[0], stop[1], stop[1], stop[2]), walk(6))  # Alice hovers at a vertex
    return routes


def write_paper_shaped(directory: Path, seed: int) -> PaperShaped:
    """The paper's layout in ``directory`` (made if missing), from ``seed``."""
    rng = random.Random(seed)
    directory.mkdir(parents=True, exist_ok=True)
    pairs, routes = _pairs(rng), _routes(rng)
    (directory / "alices_segments.txt").write_text("\n".join(_text(a) for a, _ in pairs) + "\n")
    (directory / "bobs_segments.txt").write_text("\n".join(_text(b) for _, b in pairs) + "\n")
    bits = ""
    for a, b in pairs:
        hit = path_hits(a, b)
        assert hit == shapely_hits(a, b), (a, b)
        bits += "1" if hit[0] else "0"
    route_hits, rows = {}, []
    for k, (a, b) in routes.items():
        (directory / f"ownroute{k}.txt").write_text(_text(a))
        (directory / f"cryptroute{k}.txt").write_text(_text(b))
        hits = path_hits(a, b)
        assert hits == shapely_hits(a, b), (a, b)
        route_hits[k] = [i for i, h in enumerate(hits) if h]
        rows.append(f"data/ownroute{k}.txt,data/cryptroute{k}.txt,{str(any(hits)).lower()}")
    rng.shuffle(rows)  # as the paper's file, in no particular order
    (directory / "testroutine.csv").write_text("\n".join(rows))
    return PaperShaped(directory, bits, route_hits)
