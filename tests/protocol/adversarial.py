"""Hand-picked degenerate segment pairs: every case the closed-segment predicate must get right."""

from __future__ import annotations

from protocol.geo.geometry import Point

Pair = tuple[Point, Point, Point, Point]

R = 99  # coordinates stay within +-R

ADVERSARIAL: list[tuple[str, Pair]] = [
    ("proper crossing", ((0, 0), (10, 10), (0, 10), (10, 0))),
    ("disjoint parallel", ((0, 0), (10, 0), (0, 1), (10, 1))),
    ("collinear overlapping", ((0, 0), (10, 0), (5, 0), (15, 0))),
    ("collinear disjoint", ((0, 0), (4, 0), (5, 0), (9, 0))),
    ("collinear touching end to end", ((0, 0), (5, 0), (5, 0), (9, 0))),
    ("collinear contained", ((0, 0), (10, 10), (3, 3), (4, 4))),
    ("collinear containing", ((3, 3), (4, 4), (0, 0), (10, 10))),
    ("collinear diagonal disjoint", ((0, 0), (2, 2), (3, 3), (5, 5))),
    ("collinear vertical overlap", ((7, -5), (7, 5), (7, 4), (7, 9))),
    ("collinear vertical disjoint", ((7, -5), (7, 3), (7, 4), (7, 9))),
    ("touching endpoints", ((0, 0), (5, 5), (5, 5), (9, 0))),
    ("T-junction", ((0, 0), (10, 0), (5, 0), (5, 7))),
    ("T-junction, stem one short", ((0, 0), (10, 0), (5, 1), (5, 7))),
    ("T from the other side", ((5, 0), (5, 7), (0, 0), (10, 0))),
    ("identical", ((1, 2), (30, 40), (1, 2), (30, 40))),
    ("reversed", ((1, 2), (30, 40), (30, 40), (1, 2))),
    ("Alice zero-length on Bob", ((5, 0), (5, 0), (0, 0), (10, 0))),
    ("Alice zero-length on Bob's endpoint", ((10, 0), (10, 0), (0, 0), (10, 0))),
    ("Alice zero-length off Bob, collinear", ((11, 0), (11, 0), (0, 0), (10, 0))),
    ("Alice zero-length off Bob", ((5, 1), (5, 1), (0, 0), (10, 0))),
    ("Bob zero-length on Alice", ((0, 0), (10, 10), (4, 4), (4, 4))),
    ("Bob zero-length off Alice, collinear", ((0, 0), (10, 10), (11, 11), (11, 11))),
    ("Bob zero-length off Alice", ((0, 0), (10, 10), (4, 5), (4, 5))),
    ("both zero-length, same point", ((3, 3), (3, 3), (3, 3), (3, 3))),
    ("both zero-length, different points", ((3, 3), (3, 3), (3, 4), (3, 4))),
    ("shared vertex, different directions", ((0, 0), (5, 5), (0, 0), (-5, 3))),
    ("horizontal and vertical crossing", ((-9, 0), (9, 0), (0, -9), (0, 9))),
    ("horizontal and vertical near miss", ((-9, 0), (9, 0), (10, -9), (10, 9))),
    ("extreme corners crossing", ((-R, -R), (R, R), (-R, R), (R, -R))),
    ("extreme collinear overlap", ((-R, -R), (R, R), (0, 0), (R, R))),
    ("extreme collinear touch", ((-R, R), (0, 0), (0, 0), (R, -R))),
    ("extreme near-parallel miss", ((-R, -R), (R, R - 1), (-R, -R + 1), (R, R))),
    ("extreme zero-length at a corner", ((R, R), (R, R), (-R, -R), (R, R))),
]
