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
:mod:`protocol.pathcircuit`; :func:`circuit` evaluates it on plain bits and is tested against
:func:`segments_intersect` and shapely.  For A = B the projection uses e = (1, K) with K larger
than any coordinate difference and T = 0: an injective, order-preserving key along any line
through A.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from fractions import Fraction

Point = tuple[int, int]
Polyline = tuple[Point, ...]


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


def comparison_bits(a: Point, b: Point, c: Point, d: Point, span: int) -> list[int]:
    """The input bits of :func:`protocol.pathcircuit.segments_meet` for one segment pair:
    P, Z of o1 .. o4, then L, H of t_C and t_D."""
    bits = []
    for o in (orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)):
        bits += [int(o > 0), int(o == 0)]
    ex, ey, off, t_max = projection_key(a, b, span)
    for p in (c, d):
        t = ex * p[0] + ey * p[1] + off
        bits += [int(t < 0), int(t > t_max)]
    return bits


def circuit(a: Point, b: Point, c: Point, d: Point, span: int) -> int:
    """The protocol's circuit (:mod:`protocol.pathcircuit`) evaluated on plain bits."""
    from .circuit import Circuit
    from .pathcircuit import Orient, Proj, segments_meet

    c_ = Circuit()
    wires = [c_.input() for _ in range(12)]
    o1, o2, o3, o4 = (Orient(wires[2 * j], wires[2 * j + 1]) for j in range(4))
    c_.output(
        segments_meet(c_, o1, o2, o3, o4, Proj(wires[8], wires[9]), Proj(wires[10], wires[11]))
    )
    return c_.evaluate(comparison_bits(a, b, c, d, span))[0]


# --------------------------------------------------------------------------- the public box


FPoint = tuple[Fraction, Fraction]


def _clip(p: Point, q: Point, r: int) -> tuple[FPoint, FPoint] | None:
    """Liang-Barsky: the part of segment pq inside [-r, r]^2, exactly (None if none)."""
    t0, t1 = Fraction(0), Fraction(1)
    dx, dy = q[0] - p[0], q[1] - p[1]
    for step, room in ((-dx, p[0] + r), (dx, r - p[0]), (-dy, p[1] + r), (dy, r - p[1])):
        if step == 0:
            if room < 0:
                return None
            continue
        t = Fraction(room, step)
        if step < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 > t1:
            return None
    return (p[0] + t0 * dx, p[1] + t0 * dy), (p[0] + t1 * dx, p[1] + t1 * dy)


def _round_in(point: FPoint, r: int) -> Point:
    return (max(-r, min(r, round(point[0]))), max(-r, min(r, round(point[1]))))


def _perimeter(p: Point, r: int) -> int:
    """Position of a boundary point along the box edge, counter-clockwise from (r, -r)."""
    x, y = p
    if x == r:
        return y + r
    if y == r:
        return 2 * r + (r - x)
    if x == -r:
        return 4 * r + (r - y)
    return 6 * r + (x + r)


def _walk(p: Point, q: Point, r: int) -> list[Point]:
    """Corners passed going from boundary point p to boundary point q the shorter way."""
    corners = [(r, r), (-r, r), (-r, -r), (r, -r)]  # at perimeter 2r, 4r, 6r, 8r = 0
    total = 8 * r
    a, b = _perimeter(p, r), _perimeter(q, r)
    forward = (b - a) % total
    out = []
    if forward <= total - forward:
        for k, corner in enumerate(corners):
            if 0 < (2 * r * (k + 1) - a) % total < forward:
                out.append(corner)
        out.sort(key=lambda c: (_perimeter(c, r) - a) % total)
    else:
        for k, corner in enumerate(corners):
            if 0 < (a - 2 * r * (k + 1)) % total < total - forward:
                out.append(corner)
        out.sort(key=lambda c: (a - _perimeter(c, r)) % total)
    return out


def clip_to_box(path: Sequence[Point], r: int) -> tuple[Point, ...]:
    """Bob's path as far as it lies in the public box [-r, r]^2.

    Segments inside are kept exactly.  A segment that leaves the box is cut at the edge and the
    cut point rounded to the grid (at most half a cell, as every waypoint is); where the path is
    outside, it is replaced by a walk along the edge, which Alice's path (inside the box) can
    only touch where it reaches the edge itself -- a false alarm at worst, never a missed
    crossing.  A path entirely outside becomes the single corner (r, r).
    """
    if all(abs(x) <= r and abs(y) <= r for x, y in path):
        return tuple(path)
    out: list[Point] = []
    for p, q in itertools.pairwise(path):
        part = _clip(p, q, r)
        if part is None:
            continue
        a, b = _round_in(part[0], r), _round_in(part[1], r)
        if out and out[-1] != a:
            out += _walk(out[-1], a, r)
        if not out or out[-1] != a:
            out.append(a)
        out.append(b)
    return tuple(out) if out else ((r, r), (r, r))
