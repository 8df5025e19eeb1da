"""Plane geometry on the integer grid: the predicate the encrypted protocol computes.

Everything here is plaintext and exact (Python integers, no floating point).  Two uses:

* :func:`segments_intersect` / :func:`path_hits` -- the closed-segment predicate, the reference
  the encrypted protocol must agree with (``plain_hits`` in the CLI output);
* the *linear forms* (paper, section IV-B, eq. for the orientation) that make every secret
  quantity a linear function of the other party's encrypted coordinates:

  - ``orient(A, B, P) = alpha * Px + beta * Py + gamma`` with alpha = -(By - Ay),
    beta = Bx - Ax, gamma = (By - Ay) Ax - (Bx - Ax) Ay  -- Alice's segment, Bob's point;
  - ``orient(C, D, A) = Ay * dX - Ax * dY + K`` with dX = Dx - Cx, dY = Dy - Cy and
    K = Cx Dy - Dx Cy  -- Bob's segment (he sends dX, dY, K), Alice's point;
  - ``proj(A, B, P) = (P - A) . e`` with e = B - A -- where Bob's point lies along Alice's
    segment, used only to decide collinear overlap.

The circuit that decides a segment pair from the signs of these values is
:mod:`protocol.circuits.paths`; :func:`circuit` evaluates it on plain bits and is tested against
:func:`segments_intersect` and shapely.  For A = B the projection uses e = (1, K) with K larger
than any coordinate difference and T = 0: an injective, order-preserving key along any line
through A.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction

from protocol.circuits.boolean import Circuit
from protocol.circuits.paths import Orient, Proj, segments_meet

Point = tuple[int, int]


def orient(a: Point, b: Point, p: Point) -> int:
    """Twice the signed area of (a, b, p): > 0 left turn, < 0 right turn, 0 collinear."""
    return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])


def _on_segment(a: Point, b: Point, p: Point) -> bool:
    """p collinear with a, b lies in their bounding box."""
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])


def segments_intersect(a: Point, b: Point, c: Point, d: Point) -> bool:
    """Closed segments [a, b] and [c, d] share a point (touching and overlap count)."""
    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    if ((o1 > 0 and o2 < 0) or (o1 < 0 and o2 > 0)) and (
        (o3 > 0 and o4 < 0) or (o3 < 0 and o4 > 0)
    ):
        return True
    return (
        (o1 == 0 and _on_segment(a, b, c))
        or (o2 == 0 and _on_segment(a, b, d))
        or (o3 == 0 and _on_segment(c, d, a))
        or (o4 == 0 and _on_segment(c, d, b))
    )


def path_hits(alice: Sequence[Point], bob: Sequence[Point]) -> list[bool]:
    """For each segment of Alice's polyline: does it intersect any segment of Bob's?"""
    return [
        any(
            segments_intersect(alice[i], alice[i + 1], bob[k], bob[k + 1])
            for k in range(len(bob) - 1)
        )
        for i in range(len(alice) - 1)
    ]


# --------------------------------------------------------------------------- linear forms


def orient_coefficients(a: Point, b: Point) -> tuple[int, int, int]:
    """(alpha, beta, gamma) with orient(a, b, p) = alpha px + beta py + gamma."""
    ex, ey = b[0] - a[0], b[1] - a[1]
    return -ey, ex, ey * a[0] - ex * a[1]


def segment_terms(c: Point, d: Point) -> tuple[int, int, int]:
    """Bob's (dX, dY, K) with orient(c, d, a) = ay dX - ax dY + K."""
    return d[0] - c[0], d[1] - c[1], c[0] * d[1] - d[0] * c[1]


def projection_key(a: Point, b: Point, span: int) -> tuple[int, int, int, int]:
    """(ex, ey, offset, T): proj(p) = ex px + ey py + offset, in [0, T] on the segment.

    ``span`` bounds every coordinate difference; it sets K for a zero-length segment.
    """
    if a == b:
        ex, ey = 1, span + 1
        return ex, ey, -(ex * a[0] + ey * a[1]), 0
    ex, ey = b[0] - a[0], b[1] - a[1]
    return ex, ey, -(ex * a[0] + ey * a[1]), ex * ex + ey * ey


def comparison_bits(
    a: Point, b: Point, c: Point, d: Point, span: int, line: tuple[int, int, int] | None = None
) -> list[int]:
    """The input bits of :func:`protocol.circuits.paths.segments_meet` for one segment pair:
    P, Z of o1 .. o4, then L, H of t_C and t_D.  ``line``: the (dX, dY, K) Bob sends for his
    segment (default: :func:`segment_terms` of c, d), from which o3 and o4 are computed."""
    dx, dy, k = segment_terms(c, d) if line is None else line
    bits = []
    for o in (
        orient(a, b, c),
        orient(a, b, d),
        a[1] * dx - a[0] * dy + k,
        b[1] * dx - b[0] * dy + k,
    ):
        bits += [int(o > 0), int(o == 0)]
    ex, ey, off, t_max = projection_key(a, b, span)
    for p in (c, d):
        t = ex * p[0] + ey * p[1] + off
        bits += [int(t < 0), int(t > t_max)]
    return bits


def circuit(a: Point, b: Point, c: Point, d: Point, span: int) -> int:
    """The protocol's circuit (:mod:`protocol.circuits.paths`) evaluated on plain bits."""
    return circuit_with_line(a, b, c, d, segment_terms(c, d), span)


def circuit_with_line(
    a: Point, b: Point, c: Point, d: Point, line: tuple[int, int, int], span: int
) -> int:
    """The circuit on plain bits with Bob's segment sent as ``line`` (a link's, say)."""
    c_ = Circuit()
    wires = [c_.input() for _ in range(12)]
    o1, o2, o3, o4 = (Orient(wires[2 * j], wires[2 * j + 1]) for j in range(4))
    c_.output(
        segments_meet(c_, o1, o2, o3, o4, Proj(wires[8], wires[9]), Proj(wires[10], wires[11]))
    )
    return c_.evaluate(comparison_bits(a, b, c, d, span, line))[0]


# --------------------------------------------------------------------------- the public box


FPoint = tuple[Fraction, Fraction]


def _clip(p: Point, q: Point, r: int) -> tuple[bool, FPoint, FPoint]:
    """Liang-Barsky: the part of segment pq inside [-r, r]^2, exactly, and whether there is
    one.  The same work whether or not the segment meets the box (no early exit: Bob's time
    must not tell where his path lies); outside, the points are meaningless."""
    t0, t1 = Fraction(0), Fraction(1)
    dx, dy = q[0] - p[0], q[1] - p[1]
    outside = False
    for step, room in ((-dx, p[0] + r), (dx, r - p[0]), (-dy, p[1] + r), (dy, r - p[1])):
        t = Fraction(room, step or 1)
        outside |= step == 0 and room < 0
        if step < 0:
            t0 = max(t0, t)
        elif step > 0:
            t1 = min(t1, t)
    # t0 only grows and t1 only shrinks: crossed at any step is crossed at the end
    outside |= t0 > t1
    return not outside, (p[0] + t0 * dx, p[1] + t0 * dy), (p[0] + t1 * dx, p[1] + t1 * dy)


def _round_in(point: FPoint, r: int) -> Point:
    return (max(-r, min(r, round(point[0]))), max(-r, min(r, round(point[1]))))


def pad_path(path: Sequence[Point], segments: int) -> tuple[Point, ...]:
    """Repeat the last vertex: zero-length segments at an existing vertex change no answer."""
    return tuple(path) + (path[-1],) * (segments + 1 - len(path))


DEAD_LINE = (0, 0, 1)  # (dX, dY, K) of a link: orient(C, D, A) = 1 for every A, never a hit


@dataclass(frozen=True, slots=True)
class BobPath:
    """Bob's path as the protocol takes it: ``points`` on the grid (inside the public box,
    padded to the public size n), and which segments are *links* between separate pieces.

    A link k keeps vertices k and k + 1 where the pieces end and begin but sends the line
    terms :data:`DEAD_LINE` instead of its own: every orient(C, D, A_j) is then 1, so s34 = 0
    and col = 0 in :mod:`protocol.circuits.paths` and the pair never meets -- a link costs one
    segment of the public size and shows nothing.  ``everywhere``: Bob could not fit his path
    into n segments; the protocol then answers *meets* for every one of Alice's segments
    (segment 0 is a link and Bob's flag input turns its wire to 1): a false alarm, never a
    missed crossing, in a run that looks like any other.  ``bands`` and ``windows``: per
    segment, a cut piece keeps its segment's, padding the last one's (:mod:`protocol.geo.volumes`).
    """

    points: tuple[Point, ...]
    links: frozenset[int] = frozenset()
    everywhere: bool = False
    bands: tuple[tuple[int, int], ...] | None = None
    windows: tuple[tuple[int, int], ...] | None = None

    @property
    def segments(self) -> int:
        return len(self.points) - 1

    def line(self, k: int) -> tuple[int, int, int]:
        """(dX, dY, K) Bob sends for segment k (:func:`segment_terms`, or a link's)."""
        if k in self.links:
            return DEAD_LINE
        return segment_terms(self.points[k], self.points[k + 1])

    def hits(self, alice: Sequence[Point]) -> list[bool]:
        """The plaintext answer this path gives Alice (the reference for tests)."""
        live = [k for k in range(self.segments) if k not in self.links]
        return [
            self.everywhere
            or any(
                segments_intersect(alice[i], alice[i + 1], self.points[k], self.points[k + 1])
                for k in live
            )
            for i in range(len(alice) - 1)
        ]


Intervals = Sequence[tuple[int, int]] | None


def fit_to_box(
    path: Sequence[Point], r: int, n: int, bands: Intervals = None, windows: Intervals = None
) -> BobPath:
    """Bob's path as far as it lies in the public box [-r, r]^2, in exactly n segments.

    ``n`` is the public size, chosen from Bob's own path alone (never from where it lies), so
    Alice cannot tell from the run whether his path leaves her box.  Each segment is cut to the
    box exactly (Liang-Barsky), the cut points rounded to the grid -- at most half a cell, as
    every waypoint is; pieces that do not share an end are joined by links (see
    :class:`BobPath`), so the answer inside the box is that of the uncut path.  Whatever
    does not fit into n segments makes the answer *meets everywhere*; a path with nothing in
    the box is a link at a corner, which meets nothing.  ``bands`` and ``windows`` (one per
    segment of ``path``) follow the pieces.  Every segment costs the same clipping and
    rounding whether it lies in the box or not: how long Bob takes does not tell Alice where
    his path lies.
    """
    if n < 1:
        raise ValueError("a path has at least one segment")
    points: list[Point] = []
    links: set[int] = set()
    owner: list[int] = []  # per kept segment: the segment of ``path`` it comes from
    for s, (p, q) in enumerate(itertools.pairwise(path)):
        inside, fa, fb = _clip(p, q, r)
        a, b = _round_in(fa, r), _round_in(fb, r)  # (rounded either way: the same work)
        if not inside:
            continue
        if points and points[-1] != a:
            links.add(len(points) - 1)
            points.append(a)
            owner.append(s)
        elif not points:
            points.append(a)
        points.append(b)
        owner.append(s)

    def follow(intervals: Intervals, kept: Sequence[int]) -> tuple[tuple[int, int], ...] | None:
        if intervals is None:
            return None
        out = [intervals[s] for s in kept] or [intervals[-1]]
        return tuple(out + [out[-1]] * (n - len(out)))

    if not points or len(points) - 1 > n:  # nothing in the box, or too much: all links
        return BobPath(
            ((r, r),) * (n + 1),
            frozenset(range(n)),
            bool(points),
            follow(bands, ()),
            follow(windows, ()),
        )
    return BobPath(
        pad_path(points, n), frozenset(links), False, follow(bands, owner), follow(windows, owner)
    )
