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

The circuit (see ``docs/security.md``): with G = [o >= 0], P = [o >= 1], Z = G xor P = [o = 0],

    s12 = 1 - P1 P2 - (1 - G1)(1 - G2)         (C and D not strictly on one side of AB)
    s34 = 1 - P3 P4 - (1 - G3)(1 - G4)         (A and B not strictly on one side of CD)
    col = Z1 Z2  (A != B)   or   Z3 Z4  (A = B)
    w   = L_C L_D + H_C H_D,   L = [t < 0], H = [t >= T + 1]   (projection misses [0, T])
    I   = s12 s34 - col w

For A = B the projection uses e = (1, K) with K larger than any coordinate difference and
T = 0: an injective, order-preserving key along any line through A.  :func:`circuit` evaluates
this on plaintext and is tested against :func:`segments_intersect` and shapely.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

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


@dataclass(frozen=True, slots=True)
class SignBits:
    """G = [o >= 0] and P = [o >= 1] of one orientation value."""

    g: int
    p: int

    @property
    def z(self) -> int:
        return self.g ^ self.p

    @classmethod
    def of(cls, o: int) -> SignBits:
        return cls(int(o >= 0), int(o >= 1))


def side_test(first: SignBits, second: SignBits) -> int:
    """s = 1 - P1 P2 - (1 - G1)(1 - G2): the two points are not strictly on one side."""
    return 1 - first.p * second.p - (1 - first.g) * (1 - second.g)


def circuit(a: Point, b: Point, c: Point, d: Point, span: int) -> int:
    """The protocol's formula I = s12 s34 - col w on plaintext (see the module docstring)."""
    o1, o2 = SignBits.of(orient(a, b, c)), SignBits.of(orient(a, b, d))
    o3, o4 = SignBits.of(orient(c, d, a)), SignBits.of(orient(c, d, b))
    ex, ey, off, t_max = projection_key(a, b, span)
    t_c, t_d = ex * c[0] + ey * c[1] + off, ex * d[0] + ey * d[1] + off
    low = int(t_c < 0) * int(t_d < 0)
    high = int(t_c >= t_max + 1) * int(t_d >= t_max + 1)
    col = o1.z * o2.z if a != b else o3.z * o4.z
    return side_test(o1, o2) * side_test(o3, o4) - col * (low + high)
