"""Gadgets on XOR-shared bits: x = a XOR b with a held by Alice and b by Bob.

* NOT and XOR are local: NOT flips Alice's share, XOR xors the shares on each side.
* Any two-input gate f (AND, OR, ...) takes one round trip (:class:`GateBob`,
  :class:`GateAlice`): Bob sends [b1], [b2], [b1 b2] under his zero-test scheme; for a fresh
  uniform mask a', Alice needs g(b1, b2) = f(a1 XOR b1, a2 XOR b2) XOR a', which is multilinear:
      g = g00 + (g10 - g00) b1 + (g01 - g00) b2 + (g11 - g10 - g01 + g00) b1 b2,
  a linear form in Bob's ciphertexts with coefficients from Alice's truth table.  She
  re-randomises it and Bob zero-tests it: his new share is b' = g, uniform because a' is.
  The same three coefficients are computed for every gate, whatever the shares.
* Opening to Alice only: Bob sends his shares (uniform bits, meaningless alone).
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Generic

from .encoding import Reader
from .errors import LocalProtocolError, RemoteProtocolError
from .zerotest import C, ZeroTestPrivateKey, ZeroTestPublicKey

TruthTable = tuple[int, int, int, int]  # f(0,0), f(0,1), f(1,0), f(1,1)
AND: TruthTable = (0, 0, 0, 1)
OR: TruthTable = (0, 1, 1, 1)
XOR: TruthTable = (0, 1, 1, 0)


def not_share(share: int, *, alice: bool) -> int:
    """NOT x: Alice flips her share, Bob keeps his."""
    return share ^ 1 if alice else share


def xor_shares(a: int, b: int) -> int:
    """x XOR y from the same party's shares of x and y (local on both sides)."""
    return a ^ b


def _check_bits(pairs: Sequence[tuple[int, int]]) -> None:
    if any(x not in (0, 1) or y not in (0, 1) for x, y in pairs):
        raise LocalProtocolError("shares must be bits")


@dataclass(frozen=True, slots=True)
class GateInputs:
    """Bob -> Alice: [b1], [b2], [b1 b2] for each gate, as a key holder's batch."""

    payload: bytes

    def to_bytes(self) -> bytes:
        return self.payload


@dataclass(frozen=True, slots=True)
class GateOutputs(Generic[C]):
    """Alice -> Bob: [g(b1, b2)] for each gate, re-randomised."""

    ciphertexts: tuple[C, ...]

    def to_bytes(self) -> bytes:
        return b"".join(c.to_bytes() for c in self.ciphertexts)

    @classmethod
    def read(cls, reader: Reader, key: ZeroTestPublicKey[C], count: int) -> GateOutputs[C]:
        return cls(tuple(key.read_ciphertext(reader) for _ in range(count)))


class GateBob(Generic[C]):
    """Key holder's side of a batch of two-input gates."""

    def __init__(self, bits: ZeroTestPrivateKey[C], shares: Sequence[tuple[int, int]]) -> None:
        _check_bits(shares)
        self.bits = bits
        self.inputs = list(shares)
        self.outputs: list[int] | None = None

    def offer(self) -> GateInputs:
        values = [v for b1, b2 in self.inputs for v in (b1, b2, b1 * b2)]
        return GateInputs(self.bits.encrypt_batch(values))

    def finish(self, msg: GateOutputs[C]) -> list[int]:
        """Bob's output shares: 0 where g = 0, else 1."""
        if self.outputs is not None:
            raise LocalProtocolError("gate batch already finished")
        if len(msg.ciphertexts) != len(self.inputs):
            raise RemoteProtocolError("wrong number of gate outputs")
        self.outputs = [0 if self.bits.is_zero(c) else 1 for c in msg.ciphertexts]
        return list(self.outputs)


class GateAlice(Generic[C]):
    """Alice's side: evaluates each gate's truth table on Bob's encrypted shares."""

    def __init__(
        self,
        bits: ZeroTestPublicKey[C],
        shares: Sequence[tuple[int, int]],
        tables: Sequence[TruthTable],
    ) -> None:
        _check_bits(shares)
        if len(tables) != len(shares):
            raise LocalProtocolError("one truth table per gate")
        self.bits = bits
        self.inputs = list(shares)
        self.tables = list(tables)
        self.outputs: list[int] | None = None

    def evaluate(self, msg: GateInputs) -> GateOutputs[C]:
        if self.outputs is not None:
            raise LocalProtocolError("gate batch already evaluated")
        reader = Reader(msg.payload)
        enc = self.bits.read_batch(reader, 3 * len(self.inputs))
        reader.finish()
        outputs: list[int] = []
        cts: list[C] = []
        for k, ((a1, a2), f) in enumerate(zip(self.inputs, self.tables, strict=True)):
            mask = secrets.randbits(1)
            g00, g01, g10, g11 = (
                f[2 * (a1 ^ b1) + (a2 ^ b2)] ^ mask for b1 in (0, 1) for b2 in (0, 1)
            )
            b1_ct, b2_ct, b12_ct = enc[3 * k : 3 * k + 3]
            value = (g10 - g00) * b1_ct + (g01 - g00) * b2_ct + (g11 - g10 - g01 + g00) * b12_ct
            cts.append(self.bits.rerandomize(value + g00))
            outputs.append(mask)
        self.outputs = outputs
        return GateOutputs(tuple(cts))


@dataclass(frozen=True, slots=True)
class OpenedShares:
    """Bob -> Alice: Bob's shares, packed eight to a byte (LSB first)."""

    count: int
    packed: bytes

    @classmethod
    def from_shares(cls, shares: Sequence[int]) -> OpenedShares:
        _check_bits([(s, 0) for s in shares])
        value = sum(bit << i for i, bit in enumerate(shares))
        return cls(len(shares), value.to_bytes((len(shares) + 7) // 8, "little"))

    def to_bytes(self) -> bytes:
        return self.packed

    @classmethod
    def read(cls, reader: Reader, count: int) -> OpenedShares:
        packed = reader.take((count + 7) // 8)
        if int.from_bytes(packed, "little") >> count:
            raise RemoteProtocolError("padding bits of opened shares must be zero")
        return cls(count, packed)

    def open(self, alice_shares: Sequence[int]) -> list[int]:
        """The plain bits, for Alice only."""
        if len(alice_shares) != self.count:
            raise LocalProtocolError("share count mismatch")
        value = int.from_bytes(self.packed, "little")
        return [a ^ ((value >> i) & 1) for i, a in enumerate(alice_shares)]
