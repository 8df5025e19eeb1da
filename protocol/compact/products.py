"""Products of Alice's and Bob's integers as additive shares modulo 2^L, from random OTs.

Gilboa's multiplication (CRYPTO 1999) on the run's random OTs: for each bit y_j of Bob's
non-negative value y, one OT in which Bob chooses y_j.  For every product x * y that uses y
(Alice's multiplier x), Alice derives from her two keys the pads A0 (for y_j = 0) and A1 (for
y_j = 1) and sends tau = A1 - A0 - x mod 2^(L-j); Bob gets pad - y_j tau = A0 + y_j x.  With
weights 2^j, Bob holds sum 2^j (A0_j + y_j x) and Alice -sum 2^j A0_j: shares of x y mod 2^L.
Only L - j bits of the j-th message matter (higher bits vanish after the shift).

The OTs of y serve every product that uses y (one pad per product and bit, keyed by the
product's index), so a Bob value costs its bit length in OTs however often it is used.

Bob first sends y_j XOR c_j for his random choices c_j (one bit per OT); Alice's messages are
one-time padded with keys Bob does not hold, Bob's corrections with his pseudorandom choice
bits: neither side learns anything, and the shares are uniform modulo 2^L.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from protocol.errors import LocalProtocolError
from protocol.ot.extension import ChooserRots, HolderRots
from protocol.ot.hashing import pad
from protocol.wire.bitpack import pack, pack_bits, packed_size, unpack, unpack_bits


@dataclass(frozen=True, slots=True)
class Shape:
    """Public: modulus bits L, the bit length of each of Bob's values, and for each product
    which Bob value it multiplies and which output it adds to."""

    modulus_bits: int
    value_bits: tuple[int, ...]
    terms: tuple[tuple[int, int], ...]  # (Bob value, output)
    outputs: int

    def __post_init__(self) -> None:
        if any(not 0 <= v < len(self.value_bits) for v, _ in self.terms):
            raise LocalProtocolError("a product names a Bob value that does not exist")
        if any(not 0 <= o < self.outputs for _, o in self.terms):
            raise LocalProtocolError("a product names an output that does not exist")
        if any(not 1 <= b <= self.modulus_bits for b in self.value_bits):
            raise LocalProtocolError("Bob's values have 1..L bits")

    @property
    def rots(self) -> int:
        return sum(self.value_bits)

    def _offsets(self) -> list[int]:
        out, total = [], 0
        for bits in self.value_bits:
            out.append(total)
            total += bits
        return out

    def _widths(self) -> list[int]:
        return [self.modulus_bits - j for v, _ in self.terms for j in range(self.value_bits[v])]

    def correction_size(self) -> int:
        return packed_size([1] * self.rots)

    def message_size(self) -> int:
        return packed_size(self._widths())


def _label(term: int, bit: int) -> bytes:
    return term.to_bytes(4, "big") + bytes([bit])


class ProductsBob:
    """Bob: his values (non-negative, within their bit lengths) and constants per output."""

    def __init__(self, shape: Shape, values: Sequence[int], rots: ChooserRots) -> None:
        if len(values) != len(shape.value_bits) or len(rots.keys) != shape.rots:
            raise LocalProtocolError("product inputs do not match the shape")
        for value, bits in zip(values, shape.value_bits, strict=True):
            if not 0 <= value < 1 << bits:
                raise LocalProtocolError(f"Bob's value {value} does not fit in {bits} bits")
        self.shape, self.values, self.rots = shape, list(values), rots

    def corrections(self) -> bytes:
        bits = []
        index = 0
        for value, width in zip(self.values, self.shape.value_bits, strict=True):
            for j in range(width):
                bits.append(((value >> j) & 1) ^ self.rots.choices[index])
                index += 1
        return pack_bits(bits)

    def shares(self, message: bytes) -> list[int]:
        """Bob's share of each output (before his own constants)."""
        shape = self.shape
        taus = iter(unpack(message, shape._widths()))
        offsets = shape._offsets()
        modulus = 1 << shape.modulus_bits
        out = [0] * shape.outputs
        for t, (v, o) in enumerate(shape.terms):
            y = self.values[v]
            for j in range(shape.value_bits[v]):
                width = shape.modulus_bits - j
                tau = next(taus)
                u = pad(self.rots.keys[offsets[v] + j], _label(t, j), width)
                u = (u - ((y >> j) & 1) * tau) % (1 << width)
                out[o] = (out[o] + (u << j)) % modulus
        return out


class ProductsAlice:
    """Alice: one multiplier per product (any integer, taken modulo 2^L)."""

    def __init__(self, shape: Shape, multipliers: Sequence[int], rots: HolderRots) -> None:
        if len(multipliers) != len(shape.terms) or len(rots.keys0) != shape.rots:
            raise LocalProtocolError("product inputs do not match the shape")
        self.shape, self.multipliers, self.rots = shape, list(multipliers), rots

    def message(self, corrections: bytes) -> tuple[bytes, list[int]]:
        """The message for Bob and Alice's share of each output."""
        shape = self.shape
        flips = unpack_bits(corrections, shape.rots)
        offsets = shape._offsets()
        modulus = 1 << shape.modulus_bits
        taus: list[int] = []
        out = [0] * shape.outputs
        for t, ((v, o), x) in enumerate(zip(shape.terms, self.multipliers, strict=True)):
            for j in range(shape.value_bits[v]):
                width = shape.modulus_bits - j
                index = offsets[v] + j
                keys = (self.rots.keys0[index], self.rots.keys1[index])
                a0 = pad(keys[flips[index]], _label(t, j), width)
                a1 = pad(keys[1 - flips[index]], _label(t, j), width)
                taus.append((a1 - a0 - x) % (1 << width))
                out[o] = (out[o] - (a0 << j)) % modulus
        return pack(taus, shape._widths()), out
