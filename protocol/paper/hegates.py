"""Evaluating a circuit on XOR shares with homomorphic gates (the paper suite's engine).

One round trip per AND level.  Bob sends, under his DGK key, his shares b_w of every wire
the level's ANDs read and, per gate, the product b_u b_v.  For a fresh uniform mask m of
Alice's, the gate's output share for Bob, h = AND(a_u xor b_u, a_v xor b_v) xor m, is a
multilinear function of b_u, b_v: h = c + c1 b_u + c2 b_v + c12 b_u b_v with coefficients
from Alice's truth table (:func:`bilinear`), so Alice evaluates it on the ciphertexts,
re-randomises, and Bob's zero test gives him h: uniform, because m is.  Alice computes the
same three scalar multiplications per gate whatever her shares.  After the last level Bob
sends his shares of the outputs to Alice (packed bits).

Alice sees only DGK ciphertexts under Bob's key; Bob sees only masked bits.
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence

from protocol.circuits.boolean import Circuit, run_local
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.primitives.dgk import DGKPrivateKey, DGKPublicKey
from protocol.wire.bitpack import pack_bits, unpack_bits
from protocol.wire.encoding import Reader

Table = tuple[int, int, int, int]  # f(0,0), f(0,1), f(1,0), f(1,1)
AND: Table = (0, 0, 0, 1)


def bilinear(table: Table, known1: int, known2: int) -> tuple[int, int, int, int]:
    """Coefficients (c, c1, c2, c12) with f(k1 ^ y1, k2 ^ y2) = c + c1 y1 + c2 y2 + c12 y1 y2,
    for one party's shares k and the other's (encrypted) shares y."""
    h00, h01, h10, h11 = (
        table[2 * (known1 ^ y1) + (known2 ^ y2)] for y1 in (0, 1) for y2 in (0, 1)
    )
    return h00, h10 - h00, h01 - h00, h11 - h10 - h01 + h00


class _Engine:
    def __init__(self, circuit: Circuit, inputs: Sequence[int], *, alice: bool) -> None:
        if len(inputs) != len(circuit.inputs):
            raise LocalProtocolError("one share per input wire")
        self.circuit, self.alice = circuit, alice
        self.plan = circuit.schedule()
        self.shares = [0] * len(circuit.gates)
        for wire, share in zip(circuit.inputs, inputs, strict=True):
            self.shares[wire] = share & 1
        run_local(circuit, self.shares, self.plan[0][1], alice=alice)
        self.level = 0  # levels done

    @property
    def depth(self) -> int:
        return self.circuit.depth

    def _read_wires(self, level: int) -> list[int]:
        """Distinct wires the ANDs of ``level`` read, in first-use order."""
        seen: dict[int, None] = {}
        for wire in self.plan[level][0]:
            gate = self.circuit.gates[wire]
            seen.setdefault(gate.a)
            seen.setdefault(gate.b)
        return list(seen)


class HeGatesBob(_Engine):
    """The key holder's side."""

    def __init__(self, circuit: Circuit, key: DGKPrivateKey, inputs: Sequence[int]) -> None:
        super().__init__(circuit, inputs, alice=False)
        self.key = key

    def offer(self) -> bytes:
        """Encrypted shares and products for the next level."""
        level = self.level + 1
        if level > self.depth:
            raise LocalProtocolError("every level is done")
        values = [self.shares[w] for w in self._read_wires(level)]
        for wire in self.plan[level][0]:
            gate = self.circuit.gates[wire]
            values.append(self.shares[gate.a] & self.shares[gate.b])
        return self.key.encrypt_batch(values)

    def finish(self, data: bytes) -> None:
        """Bob's output shares of the level: 0 where Alice's ciphertext encrypts zero."""
        level = self.level + 1
        reader = Reader(data)
        outputs = self.key.public_key.read_batch(reader, len(self.plan[level][0]))
        reader.finish()
        for wire, ct in zip(self.plan[level][0], outputs, strict=True):
            self.shares[wire] = 0 if self.key.is_zero(ct) else 1
        run_local(self.circuit, self.shares, self.plan[level][1], alice=False)
        self.level = level

    def open(self) -> bytes:
        if self.level != self.depth:
            raise LocalProtocolError("outputs are ready after the last level")
        return pack_bits([self.shares[w] for w in self.circuit.outputs])


class HeGatesAlice(_Engine):
    """Alice's side: evaluates each gate's truth table on Bob's encrypted shares."""

    def __init__(self, circuit: Circuit, key: DGKPublicKey, inputs: Sequence[int]) -> None:
        super().__init__(circuit, inputs, alice=True)
        self.key = key

    def evaluate(self, data: bytes) -> bytes:
        level = self.level + 1
        if level > self.depth:
            raise RemoteProtocolError("no gate level is left")
        reads = self._read_wires(level)
        ands = self.plan[level][0]
        reader = Reader(data)
        enc = self.key.read_batch(reader, len(reads) + len(ands))
        reader.finish()
        single = dict(zip(reads, enc, strict=False))
        out = []
        for wire, product in zip(ands, enc[len(reads) :], strict=True):
            gate = self.circuit.gates[wire]
            mask = secrets.randbits(1)
            table: Table = tuple(v ^ mask for v in AND)  # type: ignore[assignment]
            c, c1, c2, c12 = bilinear(table, self.shares[gate.a], self.shares[gate.b])
            value = single[gate.a] * c1 + single[gate.b] * c2 + product * c12 + c
            out.append(self.key.rerandomize(value).to_bytes())
            self.shares[wire] = mask
        run_local(self.circuit, self.shares, self.plan[level][1], alice=True)
        self.level = level
        return b"".join(out)

    def open(self, data: bytes) -> list[int]:
        """Alice's plain outputs from Bob's shares."""
        if self.level != self.depth:
            raise LocalProtocolError("outputs are ready after the last level")
        bob = unpack_bits(data, len(self.circuit.outputs))
        return [self.shares[w] ^ b for w, b in zip(self.circuit.outputs, bob, strict=True)]
