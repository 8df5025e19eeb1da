"""Comparing Bob's l-bit value with Alice's on XOR shares: radix-2^w leaves and an AND tree.

For each compared value (each with its own public l) Bob holds an l-bit B and Alice one l-bit
T per threshold; the result
is XOR shares of GT = [B > T] and EQ = [B = T] (CrypTFlow2's millionaires' protocol, Rathee et
al., CCS 2020, algorithm 1, with Bob as the OT receiver so that one set of leaves serves every
threshold of a value).

*Leaves* (:class:`LeavesBob`, :class:`LeavesAlice`).  B is cut into digits of at most ``w``
bits, most significant first; each digit is one 1-out-of-2^w OT built from w random OTs
(Naor-Pinkas style: entry y is padded with a hash of the w keys Bob would hold for y, so every
entry but Bob's has a key he lacks).  Bob first sends his digit bits XOR his random choice bits
(w bits per digit); Alice then sends, per digit, 2^w entries holding, for every threshold,
[y > t_d] and [y = t_d] XOR her fresh random shares.  Bob's entry is his share.

*Tree* (:func:`build_tree`).  With (gt, eq) of a high and a low part,
GT = gt_hi xor (eq_hi AND gt_lo) and EQ = eq_hi AND eq_lo (the two ANDs share eq_hi, which
:mod:`protocol.compact.gmw` turns into one grouped triple).  A balanced tree has depth ceil(log2 q)
for q digits; EQ at the root only when asked for.

Alice sees w bits per digit that are Bob's digit XOR pseudorandom choice bits; Bob sees one
entry per digit that is a fresh random share: neither learns anything about the other's value.
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.circuits.boolean import Circuit
from protocol.errors import LocalProtocolError
from protocol.ot.extension import ChooserRots, HolderRots
from protocol.ot.hashing import pad
from protocol.wire.bitpack import pack, pack_bits, packed_size, unpack, unpack_bits

DEFAULT_DIGIT_BITS = 4
MAX_DIGIT_BITS = 8


def digit_widths(l: int, w: int) -> list[int]:
    """Digit widths, most significant first: the top digit takes the remainder."""
    if not 1 <= w <= MAX_DIGIT_BITS or l < 1:
        raise LocalProtocolError(f"digits of 1..{MAX_DIGIT_BITS} bits for l >= 1")
    q = -(-l // w)
    return [l - w * (q - 1)] + [w] * (q - 1)


def digits(value: int, widths: Sequence[int]) -> list[int]:
    out = []
    shift = sum(widths)
    for width in widths:
        shift -= width
        out.append((value >> shift) & ((1 << width) - 1))
    return out


@dataclass(frozen=True, slots=True)
class Shape:
    """Public: per compared value its bit length l, its digit widths (most significant
    first) and its number of thresholds."""

    bits: tuple[int, ...]
    digits: tuple[tuple[int, ...], ...]
    thresholds: tuple[int, ...]

    @classmethod
    def of(cls, l: int | Sequence[int], w: int, thresholds: Sequence[int]) -> Shape:
        """``l``: one bit length for every value, or one per value."""
        if any(t < 1 for t in thresholds):
            raise LocalProtocolError("every value has at least one threshold")
        bits = (l,) * len(thresholds) if isinstance(l, int) else tuple(l)
        if len(bits) != len(thresholds):
            raise LocalProtocolError("one bit length per value")
        widths = {b: tuple(digit_widths(b, w)) for b in set(bits)}
        return cls(bits, tuple(widths[b] for b in bits), tuple(thresholds))

    @property
    def rots(self) -> int:
        return sum(self.bits)

    def correction_size(self) -> int:
        return packed_size([1] * self.rots)

    def _table_widths(self) -> list[int]:
        return [
            (2 * t) << w
            for t, widths in zip(self.thresholds, self.digits, strict=True)
            for w in widths
        ]

    def table_size(self) -> int:
        return packed_size(self._table_widths())


def _label(value: int, digit: int, entry: int) -> bytes:
    return value.to_bytes(4, "big") + bytes([digit]) + entry.to_bytes(2, "big")


class LeavesBob:
    """Bob: one value of its l bits per compared value."""

    def __init__(self, shape: Shape, values: Sequence[int], rots: ChooserRots) -> None:
        if len(values) != len(shape.thresholds) or len(rots.keys) != shape.rots:
            raise LocalProtocolError("leaf inputs do not match the shape")
        if any(not 0 <= v < 1 << l for v, l in zip(values, shape.bits, strict=True)):
            raise LocalProtocolError("compared values must have their l bits")
        self.shape, self.values, self.rots = shape, list(values), rots

    def corrections(self) -> bytes:
        """Every bit of every value XOR its random choice bit (digit bits least significant
        first within a digit, digits most significant first)."""
        bits = []
        index = 0
        for value, widths in zip(self.values, self.shape.digits, strict=True):
            for digit, width in zip(digits(value, widths), widths, strict=True):
                for i in range(width):
                    bits.append(((digit >> i) & 1) ^ self.rots.choices[index])
                    index += 1
        return pack_bits(bits)

    def shares(self, tables: bytes) -> list[list[list[tuple[int, int]]]]:
        """Bob's shares: per value, per threshold, per digit (gt, eq)."""
        fields = unpack(tables, self.shape._table_widths())
        out: list[list[list[tuple[int, int]]]] = []
        index = 0
        field = iter(fields)
        for v, (value, count, widths) in enumerate(
            zip(self.values, self.shape.thresholds, self.shape.digits, strict=True)
        ):
            per: list[list[tuple[int, int]]] = [[] for _ in range(count)]
            for d, (digit, width) in enumerate(zip(digits(value, widths), widths, strict=True)):
                table = next(field)
                keys = b"".join(self.rots.keys[index : index + width])
                index += width
                bits = 2 * count
                entry = (table >> (bits * ((1 << width) - 1 - digit))) & ((1 << bits) - 1)
                entry ^= pad(keys, _label(v, d, digit), bits)
                for t in range(count):
                    shift = bits - 2 - 2 * t
                    per[t].append(((entry >> (shift + 1)) & 1, (entry >> shift) & 1))
            out.append(per)
        return out


class LeavesAlice:
    """Alice: per value one T of the value's l bits per threshold."""

    def __init__(
        self,
        shape: Shape,
        thresholds: Sequence[Sequence[int]],
        rots: HolderRots,
    ) -> None:
        if len(thresholds) != len(shape.thresholds) or len(rots.keys0) != shape.rots:
            raise LocalProtocolError("leaf inputs do not match the shape")
        for ts, count, l in zip(thresholds, shape.thresholds, shape.bits, strict=True):
            if len(ts) != count or any(not 0 <= t < 1 << l for t in ts):
                raise LocalProtocolError("one l-bit value per threshold")
        self.shape, self.thresholds, self.rots = shape, [list(t) for t in thresholds], rots

    def tables(self, corrections: bytes) -> tuple[bytes, list[list[list[tuple[int, int]]]]]:
        """The tables for Bob and Alice's own shares (same layout as :meth:`LeavesBob.shares`)."""
        shape = self.shape
        flips = unpack_bits(corrections, shape.rots)
        fields: list[int] = []
        shares: list[list[list[tuple[int, int]]]] = []
        index = 0
        for v, (ts, widths) in enumerate(zip(self.thresholds, shape.digits, strict=True)):
            count = len(ts)
            bits = 2 * count
            per: list[list[tuple[int, int]]] = [[] for _ in range(count)]
            targets = [digits(t, widths) for t in ts]
            for d, width in enumerate(widths):
                k0 = self.rots.keys0[index : index + width]
                k1 = self.rots.keys1[index : index + width]
                e = flips[index : index + width]
                index += width
                fresh = secrets.randbits(bits)
                mine = [((fresh >> (2 * t + 1)) & 1, (fresh >> (2 * t)) & 1) for t in range(count)]
                for t in range(count):
                    per[t].append(mine[t])
                table = 0
                for y in range(1 << width):
                    keys = b"".join((k1 if ((y >> i) & 1) ^ e[i] else k0)[i] for i in range(width))
                    entry = 0
                    for t in range(count):
                        target = targets[t][d]
                        gt, eq = int(y > target) ^ mine[t][0], int(y == target) ^ mine[t][1]
                        entry = (entry << 2) | (gt << 1) | eq
                    table = (table << bits) | (entry ^ pad(keys, _label(v, d, y), bits))
                fields.append(table)
            shares.append(per)
        return pack(fields, shape._table_widths()), shares


@dataclass(frozen=True, slots=True)
class Node:
    gt: int
    eq: int | None


def build_tree(circuit: Circuit, leaves: Sequence[Node], *, need_eq: bool) -> Node:
    """(GT, EQ) of a number from its digits' (gt, eq) wires, most significant first."""
    if not leaves:
        raise LocalProtocolError("no digits")
    if len(leaves) == 1:
        return leaves[0] if need_eq else Node(leaves[0].gt, None)
    half = (len(leaves) + 1) // 2
    hi = build_tree(circuit, leaves[:half], need_eq=True)
    lo = build_tree(circuit, leaves[half:], need_eq=need_eq)
    assert hi.eq is not None
    gt = circuit.xor(hi.gt, circuit.and_(hi.eq, lo.gt))
    eq = circuit.and_(hi.eq, lo.eq) if need_eq and lo.eq is not None else None
    return Node(gt, eq)


def comparison_circuit(shape: Shape, *, need_eq: bool = False) -> Circuit:
    """Only the comparisons: for each value and threshold the output GT (then EQ with
    ``need_eq``); inputs in :class:`LeavesBob`'s share order.  Benchmarks and tests use it to
    run the leaves and the tree on their own."""
    circuit = Circuit()
    for count, widths in zip(shape.thresholds, shape.digits, strict=True):
        for _ in range(count):
            nodes = [Node(circuit.input(), circuit.input()) for _ in widths]
            root = build_tree(circuit, nodes, need_eq=need_eq)
            circuit.output(root.gt)
            if need_eq:
                assert root.eq is not None
                circuit.output(root.eq)
    return circuit
