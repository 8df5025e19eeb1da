"""Evaluating a circuit on XOR shares with Beaver triples made from random OTs (sans-IO).

AND of shared x, y with a triple (a, b, c = a b): both open d = x xor a and e = y xor b, then
z = c xor d b xor e a xor d e (Alice adds d e).  Triples come from the random OTs of the run
(Gilboa's product of two bits with one OT each, GMW 1987 / Beaver 1991): with Alice's keys
(K^0, K^1) and Bob's choice c of one OT, the bits s_0 = lsb K^0, s_1 = lsb K^1, s_c satisfy
s_0 xor s_c = c (s_0 xor s_1), a product of a bit of Alice's and a bit of Bob's.

*Grouped triples.* ANDs of one level that share their first input share the mask a: a group
of G gates costs 1 + G random OTs (instead of 2 G) and opens 1 + G bits per party.  OT 0 gives
a_B (Bob's choice) times Alice's G bits b_A at once (G-bit messages); OT i gives b_iB (Bob's
choice) times a_A, where a_A is fixed by OT 1 and Alice sends f_i = a_A xor s_0 xor s_1 for the
others (1 bit each, in her first message).

*Rounds.* Messages alternate, Alice first.  Each carries the sender's openings for every level
it can open by then, which is one new level per message after the first: a circuit of depth D
costs D + 1 or D + 2 messages, the last one Bob's, carrying his shares of the outputs to Alice.
Bob learns nothing (every opened bit is masked by a fresh triple bit of Alice's); Alice learns
the outputs.  Sizes depend on the circuit only (:func:`rounds`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from protocol.circuits.boolean import Circuit, run_local
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot.extension import ChooserRots, HolderRots
from protocol.wire.bitpack import pack_bits, packed_size, unpack_bits

MAX_GROUP = 64


@dataclass(frozen=True, slots=True)
class Group:
    """ANDs of one level sharing their first input ``left``."""

    left: int
    gates: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class Round:
    alice_sends: bool
    corrections: bool
    levels: tuple[int, ...]
    outputs: bool


def plan_groups(circuit: Circuit) -> list[list[Group]]:
    """Groups per level 1 .. depth (index 0 unused and empty)."""
    plan: list[list[Group]] = []
    for ands, _ in circuit.schedule():
        by_left: dict[int, list[int]] = {}
        for wire in ands:
            by_left.setdefault(circuit.gates[wire].a, []).append(wire)
        groups = []
        for left, wires in by_left.items():
            for start in range(0, len(wires), MAX_GROUP):
                groups.append(Group(left, tuple(wires[start : start + MAX_GROUP])))
        plan.append(groups)
    return plan


def rot_count(circuit: Circuit) -> int:
    return sum(1 + len(g.gates) for level in plan_groups(circuit) for g in level)


def rounds(depth: int) -> list[Round]:
    """Who sends which openings when (public: a function of the depth only)."""
    own = {True: 0, False: 0}  # highest level whose openings a party has computed
    peer = {True: 0, False: 0}  # highest level of the other party's openings it holds
    done = {True: 0, False: 0}
    schedule: list[Round] = []
    alice = True
    while True:
        first = own[alice] + 1
        while done[alice] < depth:
            own[alice] = max(own[alice], done[alice] + 1)
            if peer[alice] >= done[alice] + 1:
                done[alice] += 1
            else:
                break
        outputs = not alice and done[alice] == depth
        schedule.append(Round(alice, not schedule, tuple(range(first, own[alice] + 1)), outputs))
        peer[not alice] = own[alice]
        if outputs:
            return schedule
        alice = not alice


def _bits(key: bytes, count: int) -> int:
    return int.from_bytes(key, "big") & ((1 << count) - 1)


class Gmw:
    """One party's evaluation of ``circuit``; ``rots`` are the OTs reserved for its triples."""

    def __init__(
        self,
        circuit: Circuit,
        *,
        alice: bool,
        rots: HolderRots | ChooserRots,
        inputs: Sequence[int],
    ) -> None:
        if len(inputs) != len(circuit.inputs):
            raise LocalProtocolError("one share per input wire")
        self.circuit, self.alice = circuit, alice
        self.plan = plan_groups(circuit)
        self.schedule = rounds(circuit.depth)
        self.depth = circuit.depth
        self._local = [local for _, local in circuit.schedule()]
        self.shares = [0] * len(circuit.gates)
        for wire, share in zip(circuit.inputs, inputs, strict=True):
            self.shares[wire] = share & 1
        run_local(circuit, self.shares, self._local[0], alice=alice)
        self._own: dict[int, list[int]] = {}
        self._peer: dict[int, list[int]] = {}
        self._done = 0
        self._next = 0
        self._opened: list[int] | None = None
        self._prepare(rots)

    # ---------------------------------------------------------------- triples

    def _prepare(self, rots: HolderRots | ChooserRots) -> None:
        """Per group: my a, my b_i, my c_i except Bob's f-dependent part (added later)."""
        self._a: list[list[int]] = [[] for _ in self.plan]
        self._b: list[list[list[int]]] = [[] for _ in self.plan]
        self._c: list[list[list[int]]] = [[] for _ in self.plan]
        self.corrections: list[int] = []
        index = 0
        needed = rot_count(self.circuit)
        if isinstance(rots, HolderRots):
            if not self.alice or len(rots.keys0) != needed:
                raise LocalProtocolError("Alice needs exactly the triples' random OTs")
        elif self.alice or len(rots.keys) != needed:
            raise LocalProtocolError("Bob needs exactly the triples' random OTs")
        for level, groups in enumerate(self.plan):
            for group in groups:
                size = len(group.gates)
                if isinstance(rots, HolderRots):
                    s0, s1 = _bits(rots.keys0[index], size), _bits(rots.keys1[index], size)
                    t = [
                        (_bits(rots.keys0[index + i], 1), _bits(rots.keys1[index + i], 1))
                        for i in range(1, size + 1)
                    ]
                    a = t[0][0] ^ t[0][1]
                    b = [((s0 ^ s1) >> i) & 1 for i in range(size)]
                    c = [(a & b[i]) ^ ((s0 >> i) & 1) ^ t[i][0] for i in range(size)]
                    self.corrections += [a ^ t0 ^ t1 for t0, t1 in t[1:]]
                else:
                    a = rots.choices[index]
                    sc = _bits(rots.keys[index], size)
                    b = [rots.choices[index + i] for i in range(1, size + 1)]
                    c = [
                        (a & b[i]) ^ ((sc >> i) & 1) ^ _bits(rots.keys[index + 1 + i], 1)
                        for i in range(size)
                    ]
                self._a[level].append(a)
                self._b[level].append(b)
                self._c[level].append(c)
                index += 1 + size

    def _apply_corrections(self, f: Sequence[int]) -> None:
        """Bob: c_iB gets b_iB f_i for every triple but the first of its group."""
        feed = iter(f)
        for level, groups in enumerate(self.plan):
            for g, group in enumerate(groups):
                for i in range(1, len(group.gates)):
                    self._c[level][g][i] ^= self._b[level][g][i] & next(feed)

    # ---------------------------------------------------------------- levels

    def _openings(self, level: int) -> list[int]:
        out: list[int] = []
        for g, group in enumerate(self.plan[level]):
            out.append(self.shares[group.left] ^ self._a[level][g])
            for i, wire in enumerate(group.gates):
                out.append(self.shares[self.circuit.gates[wire].b] ^ self._b[level][g][i])
        return out

    def _advance(self) -> None:
        while self._done < self.depth:
            level = self._done + 1
            if level not in self._own:
                self._own[level] = self._openings(level)
            if level not in self._peer:
                return
            opened = [x ^ y for x, y in zip(self._own[level], self._peer[level], strict=True)]
            feed = iter(opened)
            for g, group in enumerate(self.plan[level]):
                d = next(feed)
                a = self._a[level][g]
                for i, wire in enumerate(group.gates):
                    e = next(feed)
                    b, c = self._b[level][g][i], self._c[level][g][i]
                    self.shares[wire] = c ^ (d & b) ^ (e & a) ^ (d & e & int(self.alice))
            run_local(self.circuit, self.shares, self._local[level], alice=self.alice)
            self._done = level

    def _level_size(self, level: int) -> int:
        return sum(1 + len(g.gates) for g in self.plan[level])

    def _widths(self, step: Round) -> int:
        bits = sum(self._level_size(level) for level in step.levels)
        if step.corrections:
            bits += sum(len(g.gates) - 1 for level in self.plan for g in level)
        if step.outputs:
            bits += len(self.circuit.outputs)
        return bits

    # ---------------------------------------------------------------- messages

    @property
    def finished(self) -> bool:
        return self._next == len(self.schedule)

    def next_is_mine(self) -> bool:
        return not self.finished and self.schedule[self._next].alice_sends == self.alice

    def message_size(self, index: int) -> int:
        return packed_size([1] * self._widths(self.schedule[index]))

    def send(self) -> bytes:
        if not self.next_is_mine():
            raise LocalProtocolError("not this party's turn in the circuit evaluation")
        step = self.schedule[self._next]
        self._advance()
        bits: list[int] = []
        if step.corrections and self.alice:
            bits += self.corrections
        for level in step.levels:
            bits += self._own[level]
        if step.outputs:
            bits += [self.shares[w] for w in self.circuit.outputs]
        self._next += 1
        return pack_bits(bits)

    def receive(self, data: bytes) -> None:
        if self.finished or self.next_is_mine():
            raise LocalProtocolError("not the peer's turn in the circuit evaluation")
        step = self.schedule[self._next]
        bits = unpack_bits(data, self._widths(step))
        position = 0
        if step.corrections and not self.alice:
            count = sum(len(g.gates) - 1 for level in self.plan for g in level)
            self._apply_corrections(bits[:count])
            position = count
        for level in step.levels:
            size = self._level_size(level)
            self._peer[level] = bits[position : position + size]
            position += size
        if step.outputs:
            if not self.alice:
                raise RemoteProtocolError("Bob does not receive outputs")
            self._opened = bits[position:]
        self._next += 1
        self._advance()

    def outputs(self) -> list[int]:
        """Alice's plain outputs, once Bob's shares arrived."""
        if not self.alice or self._opened is None:
            raise LocalProtocolError("outputs are Alice's, after the last message")
        return [self.shares[w] ^ o for w, o in zip(self.circuit.outputs, self._opened, strict=True)]
