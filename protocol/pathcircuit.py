"""The intersection circuit of two paths, over comparison bits (paper section IV-B, done exactly).

For Alice's segment AB and Bob's segment CD, with o1 = orient(A, B, C), o2 = orient(A, B, D),
o3 = orient(C, D, A), o4 = orient(C, D, B) and t_C, t_D where C and D project on AB (see
:mod:`protocol.geometry`), the inputs are the bits

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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from .circuit import Circuit


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


def segments_meet(
    c: Circuit, o1: Orient, o2: Orient, o3: Orient, o4: Orient, tc: Proj, td: Proj
) -> int:
    """The wire I of one segment pair."""

    def negative(o: Orient) -> int:
        return c.not_(c.xor(o.p, o.z))

    def straddle(first: Orient, second: Orient) -> int:
        same = c.xor(c.and_(first.p, second.p), c.and_(negative(first), negative(second)))
        return c.not_(same)

    col = c.and_(c.and_(o1.z, o2.z), c.and_(o3.z, o4.z))
    w = c.xor(c.and_(tc.low, td.low), c.and_(tc.high, td.high))
    return c.xor(c.and_(straddle(o1, o2), straddle(o3, o4)), c.and_(col, w))


def path_hits(
    c: Circuit,
    m: int,
    n: int,
    o1: Sequence[Sequence[Orient]],
    proj: Sequence[Sequence[Proj]],
    o3: Sequence[Sequence[Orient]],
    flag: int | None = None,
) -> list[int]:
    """Output wires: for each of Alice's m segments, does it meet any of Bob's n?

    ``o1[i][k]`` orient(A_i, A_i+1, B_k) and ``proj[i][k]`` for Bob's vertex k (n + 1 of them),
    ``o3[j][k]`` orient(B_k, B_k+1, A_j) for Alice's vertex j (m + 1 of them).  ``flag`` (Bob's
    input, free XOR) flips every pair with his segment 0: he sets it only when segment 0 is a
    link (never a hit), to answer *meets* everywhere (:class:`protocol.geometry.BobPath`).
    """
    hits = []
    for i in range(m):
        pairs = [
            segments_meet(
                c, o1[i][k], o1[i][k + 1], o3[i][k], o3[i + 1][k], proj[i][k], proj[i][k + 1]
            )
            for k in range(n)
        ]
        if flag is not None:
            pairs[0] = c.xor(pairs[0], flag)
        hits.append(c.or_all(pairs))
    return hits
