"""The conflict circuit of two paths, over comparison bits (paper section IV-B, done exactly;
protected volumes, :mod:`protocol.geo.volumes`, beyond it).

For Alice's segment AB and Bob's segment CD, with o1 = orient(A, B, C), o2 = orient(A, B, D),
o3 = orient(C, D, A), o4 = orient(C, D, B) and t_C, t_D where C and D project on AB (see
:mod:`protocol.geo.geometry`), the inputs are the bits

* per orientation o: P = [o > 0], Z = [o = 0] (so N = [o < 0] = 1 xor P xor Z);
* per projection t: L = [t < 0], H = [t > T] (before A, beyond B).

    s12 = not (P1 P2 xor N1 N2)        C, D not strictly on one side of AB
    s34 = not (P3 P4 xor N3 N4)        A, B not strictly on one side of CD
    col = Z1 Z2 Z3 Z4                  all four collinear
    w   = Lc Ld xor Hc Hd              C and D both before A or both beyond B
    I   = s12 s34 xor col w

The products in s12, s34 and w are mutually exclusive, so XOR is OR; col w = 1 forces
s12 = s34 = 1, so I = s12 s34 AND NOT (col w).  A zero-length Alice segment (A = B) has
o1 = o2 = 0, so col reduces to Z3 Z4 (A on line CD); a zero-length Bob segment makes Z3 = Z4 = 1:
no branch on a secret is needed.  Alice's bit for segment i is the OR over Bob's segments k.
Eleven ANDs per segment pair, three levels above the comparisons, plus an OR tree.

*Volumes* (:func:`volume_hits`).  With a horizontal separation r > 0 the pair meets when the
segments cross -- (P1 xor P2) (P3 xor P4): one end of each strictly on the positive side of
the other's line, the other end not; this holds for every proper crossing and only where the
segments meet (then the two lines cross at one point, which lies on both segments; parallel,
collinear and zero-length pairs give P1 = P2) -- or an end point of one lies in the other's
capsule (a touching or collinear pair has an end point at distance 0, so no Z is needed):
one of the four vertex pairs within r (``disc``: [D <= r^2]), or a vertex in the *slab* of
the other's segment, [0 <= t <= L] and [|c| <= R] --
``proj`` and ``near1`` for Bob's vertices against Alice's segments, ``along3`` and ``near3``
for Alice's vertices against Bob's.  The pair then conflicts when also its altitude bands
(``bands``: both of [a_lo - v <= b_hi], [b_lo - v <= a_hi]) and its time windows
(``windows``) say so.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from protocol.circuits.boolean import Circuit


@dataclass(frozen=True, slots=True)
class Orient:
    """Wires P = [o > 0] and Z = [o = 0] of one orientation value."""

    p: int
    z: int


@dataclass(frozen=True, slots=True)
class Proj:
    """Wires L = [t < 0] and H = [t > T] of one projection value."""

    low: int
    high: int


@dataclass(frozen=True, slots=True)
class Range:
    """Wires [v >= low] and [v <= high] of one value (or of two values that belong
    together): inside when both are 1."""

    ge: int
    le: int


def _negative(c: Circuit, o: Orient) -> int:
    return c.not_(c.xor(o.p, o.z))


def segments_meet(
    c: Circuit, o1: Orient, o2: Orient, o3: Orient, o4: Orient, tc: Proj, td: Proj
) -> int:
    """The wire I of one segment pair."""

    def straddle(first: Orient, second: Orient) -> int:
        same = c.xor(c.and_(first.p, second.p), c.and_(_negative(c, first), _negative(c, second)))
        return c.not_(same)

    col = c.and_(c.and_(o1.z, o2.z), c.and_(o3.z, o4.z))
    w = c.xor(c.and_(tc.low, td.low), c.and_(tc.high, td.high))
    return c.xor(c.and_(straddle(o1, o2), straddle(o3, o4)), c.and_(col, w))


def crosses(c: Circuit, o1: Orient, o2: Orient, o3: Orient, o4: Orient) -> int:
    """(P1 xor P2) (P3 xor P4): every proper crossing, and only segments that meet (module
    docstring); touching and collinear pairs are left to the capsules.  One AND."""
    return c.and_(c.xor(o1.p, o2.p), c.xor(o3.p, o4.p))


@dataclass(frozen=True)
class Capsules:
    """The wires of the capsule tests (horizontal separation r > 0), indexed like
    :func:`volume_hits`' inputs: ``near1[i][k]`` [|orient(A_i, A_i+1, B_k)| <= R_i],
    ``near3[j][k]`` [|orient(B_k, B_k+1, A_j)| <= R'_k], ``along3[j][k]`` [0 <= (A_j - B_k).d_k
    <= L_k], ``disc[j][k]`` [|A_j - B_k|^2 <= r^2] (j <= m, k <= n)."""

    near1: Sequence[Sequence[Range]]
    near3: Sequence[Sequence[Range]]
    along3: Sequence[Sequence[Range]]
    disc: Sequence[Sequence[int]]


def volume_hits(
    c: Circuit,
    m: int,
    n: int,
    o1: Sequence[Sequence[Orient]],
    proj: Sequence[Sequence[Proj]],
    o3: Sequence[Sequence[Orient]],
    *,
    capsules: Capsules | None = None,
    bands: Sequence[Sequence[Range]] | None = None,
    windows: Sequence[Sequence[Range]] | None = None,
    flag: int | None = None,
) -> list[int]:
    """Output wires: for each of Alice's m segments, does its volume meet any of Bob's n?

    ``o1[i][k]`` orient(A_i, A_i+1, B_k) and ``proj[i][k]`` for Bob's vertex k (n + 1 of them),
    ``o3[j][k]`` orient(B_k, B_k+1, A_j) for Alice's vertex j (m + 1 of them).  Without
    ``capsules`` the pairs are decided by :func:`segments_meet` (the exact crossing, r = 0),
    with them by a crossing (P bits only) or a vertex within r (module docstring).
    ``bands[i][k]`` and ``windows[i][k]``, when given, must both be inside for the pair to
    conflict.  ``flag`` (Bob's input, free XOR) flips every pair with his segment 0: he sets it
    only when segment 0 is a link (never a hit), to answer *meets* everywhere
    (:class:`protocol.geo.geometry.BobPath`)."""
    if capsules is None:
        pair = _exact_pair(c, o1, proj, o3)
    else:
        pair = _capsule_pair(c, m, n, o1, proj, o3, capsules)
    hits = []
    for i in range(m):
        pairs = [_conflict(c, pair(i, k), bands, windows, i, k) for k in range(n)]
        if flag is not None:
            pairs[0] = c.xor(pairs[0], flag)
        hits.append(c.or_all(pairs))
    return hits


def _exact_pair(
    c: Circuit,
    o1: Sequence[Sequence[Orient]],
    proj: Sequence[Sequence[Proj]],
    o3: Sequence[Sequence[Orient]],
) -> Callable[[int, int], int]:
    """The pair wire of segments i and k without capsules: :func:`segments_meet`."""

    def pair(i: int, k: int) -> int:
        return segments_meet(
            c, o1[i][k], o1[i][k + 1], o3[i][k], o3[i + 1][k], proj[i][k], proj[i][k + 1]
        )

    return pair


def _capsule_pair(
    c: Circuit,
    m: int,
    n: int,
    o1: Sequence[Sequence[Orient]],
    proj: Sequence[Sequence[Proj]],
    o3: Sequence[Sequence[Orient]],
    caps: Capsules,
) -> Callable[[int, int], int]:
    """The pair wire of segments i and k with capsules: a crossing, a vertex pair within r
    or a vertex in the other's slab (the slab wires are built here, before any pair)."""
    slab_a, slab_b = _slabs(c, m, n, proj, caps)

    def pair(i: int, k: int) -> int:
        return c.or_all(
            [
                crosses(c, o1[i][k], o1[i][k + 1], o3[i][k], o3[i + 1][k]),
                caps.disc[i][k],
                caps.disc[i][k + 1],
                caps.disc[i + 1][k],
                caps.disc[i + 1][k + 1],
                slab_a[i][k],
                slab_a[i][k + 1],
                slab_b[i][k],
                slab_b[i + 1][k],
            ]
        )

    return pair


def _slabs(
    c: Circuit, m: int, n: int, proj: Sequence[Sequence[Proj]], caps: Capsules
) -> tuple[list[list[int]], list[list[int]]]:
    """The slab wires: Bob's vertex k in the slab of Alice's segment i (``slab_a[i][k]``),
    Alice's vertex j in Bob's segment k's (``slab_b[j][k]``)."""
    slab_a = [
        [
            c.and_all(
                [
                    c.not_(proj[i][k].low),
                    c.not_(proj[i][k].high),
                    caps.near1[i][k].ge,
                    caps.near1[i][k].le,
                ]
            )
            for k in range(n + 1)
        ]
        for i in range(m)
    ]
    slab_b = [
        [
            c.and_all(
                [
                    caps.along3[j][k].ge,
                    caps.along3[j][k].le,
                    caps.near3[j][k].ge,
                    caps.near3[j][k].le,
                ]
            )
            for k in range(n)
        ]
        for j in range(m + 1)
    ]
    return slab_a, slab_b


def _conflict(
    c: Circuit,
    pair: int,
    bands: Sequence[Sequence[Range]] | None,
    windows: Sequence[Sequence[Range]] | None,
    i: int,
    k: int,
) -> int:
    """The pair wire ANDed with its band and window wires, when given."""
    conditions = [pair]
    for ranges in (bands, windows):
        if ranges is not None:
            conditions += [ranges[i][k].ge, ranges[i][k].le]
    return c.and_all(conditions)
