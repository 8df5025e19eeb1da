"""Boolean circuits over XOR-shared bits: the one description both suites evaluate.

Rules:

1. A wire is the output of one gate; gates are added in topological order, so a wire's
   number is also a valid evaluation order.
2. XOR and NOT are free (local: both parties XOR their shares; NOT flips Alice's share only);
   AND needs interaction.  A wire's *level* is the number of ANDs on its longest input path;
   all ANDs of one level are evaluated together (one interaction per level).
3. Inputs are XOR-shared by the engine that evaluates the circuit; the circuit knows nothing
   about who holds what.

:meth:`Circuit.evaluate` runs the circuit on plain bits (the tests' and the geometry's
reference); :mod:`protocol.compact.gmw` (Beaver triples from OT) and :mod:`protocol.paper.hegates`
(homomorphic gates) evaluate it on shares.
"""

from __future__ import annotations

import enum
import heapq
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from protocol.errors import LocalProtocolError


class Op(enum.IntEnum):
    INPUT = 0
    XOR = 1
    NOT = 2
    AND = 3


@dataclass(frozen=True, slots=True)
class Gate:
    op: Op
    a: int = -1
    b: int = -1


class Circuit:
    """An append-only boolean circuit; wires are ints."""

    def __init__(self) -> None:
        self.gates: list[Gate] = []
        self.level: list[int] = []
        self.inputs: list[int] = []
        self.outputs: list[int] = []

    def _add(self, gate: Gate, level: int) -> int:
        for wire in (gate.a, gate.b):
            if wire >= len(self.gates):
                raise LocalProtocolError("a gate may only use existing wires")
        self.gates.append(gate)
        self.level.append(level)
        return len(self.gates) - 1

    def input(self) -> int:
        wire = self._add(Gate(Op.INPUT), 0)
        self.inputs.append(wire)
        return wire

    def xor(self, a: int, b: int) -> int:
        return self._add(Gate(Op.XOR, a, b), max(self.level[a], self.level[b]))

    def not_(self, a: int) -> int:
        return self._add(Gate(Op.NOT, a), self.level[a])

    def and_(self, a: int, b: int) -> int:
        if a == b:
            raise LocalProtocolError("AND of a wire with itself")
        return self._add(Gate(Op.AND, a, b), max(self.level[a], self.level[b]) + 1)

    def or_(self, a: int, b: int) -> int:
        return self.not_(self.and_(self.not_(a), self.not_(b)))

    def and_all(self, wires: Sequence[int]) -> int:
        """AND of all ``wires``, the two of lowest level first (Huffman by level): a balanced
        tree (depth ceil(log2 len)) over wires of one level, and no deeper than needed over
        wires that are ready at different levels."""
        if not wires:
            raise LocalProtocolError("AND of nothing")
        heap = [(self.level[w], order, w) for order, w in enumerate(wires)]
        heapq.heapify(heap)
        order = len(heap)
        while len(heap) > 1:
            _, _, a = heapq.heappop(heap)
            _, _, b = heapq.heappop(heap)
            wire = self.and_(a, b)
            heapq.heappush(heap, (self.level[wire], order, wire))
            order += 1
        return heap[0][2]

    def or_all(self, wires: Sequence[int]) -> int:
        return self.not_(self.and_all([self.not_(w) for w in wires]))

    def output(self, wire: int) -> None:
        self.outputs.append(wire)

    @property
    def depth(self) -> int:
        return max((self.level[w] for w in self.outputs), default=0)

    @property
    def and_count(self) -> int:
        return sum(g.op is Op.AND for g in self.gates)

    def schedule(self) -> list[tuple[list[int], list[int]]]:
        """Per level L = 0 .. depth: (AND gates of level L, local gates of level L), each in
        wire order; level 0 has no ANDs."""
        depth = self.depth
        plan: list[tuple[list[int], list[int]]] = [([], []) for _ in range(depth + 1)]
        for wire, gate in enumerate(self.gates):
            level = self.level[wire]
            if level > depth or gate.op is Op.INPUT:
                continue
            plan[level][0 if gate.op is Op.AND else 1].append(wire)
        return plan

    def evaluate(self, inputs: Sequence[int]) -> list[int]:
        """The outputs on plain input bits."""
        if len(inputs) != len(self.inputs):
            raise LocalProtocolError("one bit per input wire")
        values = [0] * len(self.gates)
        feed = iter(inputs)
        for wire, gate in enumerate(self.gates):
            if gate.op is Op.INPUT:
                values[wire] = next(feed) & 1
            elif gate.op is Op.XOR:
                values[wire] = values[gate.a] ^ values[gate.b]
            elif gate.op is Op.NOT:
                values[wire] = values[gate.a] ^ 1
            else:
                values[wire] = values[gate.a] & values[gate.b]
        return [values[w] for w in self.outputs]


def run_local(circuit: Circuit, shares: list[int], wires: Iterable[int], *, alice: bool) -> None:
    """Evaluate the local (XOR, NOT) gates ``wires`` on one party's shares, in place."""
    for wire in wires:
        gate = circuit.gates[wire]
        if gate.op is Op.XOR:
            shares[wire] = shares[gate.a] ^ shares[gate.b]
        elif gate.op is Op.NOT:
            shares[wire] = shares[gate.a] ^ int(alice)
        else:
            raise LocalProtocolError("only XOR and NOT are local")
