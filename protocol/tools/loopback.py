"""Run both parties of a sub-protocol in one process, through the real byte encoding.

Every message is serialised with ``to_bytes`` and decoded from those bytes by the receiver, so
byte counts are what a radio would carry.  CPU time is charged to the party whose step runs.
Pure: no sockets, no clocks other than the process CPU clock used for accounting.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import TypeVar

from protocol.circuits.boolean import Circuit
from protocol.compact.gmw import Gmw, rot_count
from protocol.compact.millionaire import LeavesAlice, LeavesBob, Shape, comparison_circuit
from protocol.intersection import Alice, Bob
from protocol.messages import MsgType
from protocol.ot.extension import ChooserRots, HolderRots, chooser_extend, holder_extend
from protocol.ot.setup import ChooserSetup, HolderSetup, HolderSetupStart, chooser_setup
from protocol.paper.comparison import (
    BitDecompositions,
    BlindedTests,
    ComparisonAlice,
    ComparisonBob,
    MaskedDifferences,
)
from protocol.wire.encoding import Reader

T = TypeVar("T")


@dataclass
class Transcript:
    """Bytes and CPU seconds per direction/party, message counts and sizes, and round trips:
    the turns Alice takes (a message or several of hers, then Bob's answer) -- what costs
    radio turnarounds."""

    bytes_alice_to_bob: int = 0
    bytes_bob_to_alice: int = 0
    messages: int = 0
    round_trips: int = 0
    cpu_alice: float = 0.0
    cpu_bob: float = 0.0
    sizes: list[tuple[str, int]] = field(default_factory=list)
    _last_from_alice: bool = False

    def send(self, name: str, data: bytes, *, from_alice: bool) -> bytes:
        if from_alice:
            self.bytes_alice_to_bob += len(data)
            self.round_trips += not self._last_from_alice
        else:
            self.bytes_bob_to_alice += len(data)
        self._last_from_alice = from_alice
        self.messages += 1
        self.sizes.append((name, len(data)))
        return data

    def alice(self, step: Callable[[], T]) -> T:
        start = time.process_time()
        try:
            return step()
        finally:
            self.cpu_alice += time.process_time() - start

    def bob(self, step: Callable[[], T]) -> T:
        start = time.process_time()
        try:
            return step()
        finally:
            self.cpu_bob += time.process_time() - start


def _read_all(data: bytes, parse: Callable[[Reader], T]) -> T:
    reader = Reader(data)
    value = parse(reader)
    reader.finish()
    return value


def run_comparison(
    alice: ComparisonAlice, bob: ComparisonBob, transcript: Transcript | None = None
) -> Transcript:
    """Steps 1-4 of the comparison, every message through its bytes."""
    t = transcript or Transcript()
    wire = t.send("masked", t.alice(lambda: alice.mask().to_bytes()), from_alice=True)
    paillier = bob.paillier.public_key
    masked = t.bob(
        lambda: _read_all(wire, lambda r: MaskedDifferences.read(r, paillier, bob.masked_count()))
    )
    wire = t.send("bits", t.bob(lambda: bob.decompose(masked).to_bytes()), from_alice=False)
    wire = t.send(
        "tests",
        t.alice(lambda: alice.compare_bits(BitDecompositions(wire)).to_bytes()),
        from_alice=True,
    )
    key = bob.bits.public_key
    tests = t.bob(lambda: _read_all(wire, lambda r: BlindedTests.read(r, key, bob.tests_count())))
    t.bob(lambda: bob.zero_test(tests))
    return t


def run_ot_setup(
    blocks: Sequence[int] | None = None, transcript: Transcript | None = None
) -> tuple[ChooserSetup, HolderSetup, Transcript]:
    """The one-time OT setup of a pair (Alice holds, Bob chooses), through its bytes."""
    t = transcript or Transcript()
    holder = t.alice(lambda: HolderSetupStart() if blocks is None else HolderSetupStart(blocks))
    hello = t.send("setup", t.alice(holder.message), from_alice=True)
    chooser, reply = t.bob(lambda: chooser_setup(hello, holder.blocks))
    t.send("setup reply", reply, from_alice=False)
    return chooser, t.alice(lambda: holder.finish(reply)), t


def run_paths(alice: Alice, bob: Bob, transcript: Transcript | None = None) -> Transcript:
    """Both parties of the path protocol, frame by frame, until Alice has her answer."""
    t = transcript if transcript is not None else Transcript()
    frame: bytes | None = t.send("HELLO", t.alice(alice.start), from_alice=True)
    from_alice = True
    while frame is not None:
        receiver = bob if from_alice else alice
        account = t.bob if from_alice else t.alice
        current = frame
        frame = account(partial(receiver.receive, current))
        from_alice = not from_alice
        if frame is not None:
            t.send(MsgType(frame[3]).name, frame, from_alice=from_alice)
    return t


def run_millionaires(
    chooser: ChooserSetup,
    holder: HolderSetup,
    shape: Shape,
    bob_values: Sequence[int],
    alice_values: Sequence[Sequence[int]],
    *,
    need_eq: bool = False,
    transcript: Transcript | None = None,
) -> tuple[list[int], Transcript]:
    """The compact suite's comparisons alone: OT extension, leaves, tree (GMW), and the
    outputs opened to Alice ([b > t], then [b = t] with ``need_eq``, per value and
    threshold).  Returns Alice's plain outputs and the transcript."""
    t = transcript or Transcript()
    circuit = comparison_circuit(shape, need_eq=need_eq)
    total = shape.rots + rot_count(circuit)
    nonce = secrets.token_bytes(32)
    wire, bob_leaves, bob_triples = t.bob(
        partial(_bob_extend, chooser, nonce, total, shape, bob_values)
    )
    t.send("extension+digits", wire, from_alice=False)
    split = len(wire) - shape.correction_size()
    wire, alice_gmw = t.alice(
        partial(_alice_tables, holder, nonce, total, shape, alice_values, circuit, wire, split)
    )
    t.send("tables", wire, from_alice=True)
    size = shape.table_size()
    wire, bob_gmw = t.bob(partial(_bob_tables, bob_leaves, bob_triples, circuit, wire, size))
    t.send("round", wire, from_alice=False)
    _gmw_rounds(t, alice_gmw, bob_gmw, wire)
    return alice_gmw.outputs(), t


def _share_bits(shares: list[list[list[tuple[int, int]]]]) -> list[int]:
    """The leaves' shares as GMW inputs: per value, per threshold, per digit (gt, eq)."""
    return [bit for v in shares for th in v for pair in th for bit in pair]


def _bob_extend(
    chooser: ChooserSetup, nonce: bytes, total: int, shape: Shape, bob_values: Sequence[int]
) -> tuple[bytes, LeavesBob, ChooserRots]:
    """Bob's first step: the OT extension and his digits' corrections, his leaves and the
    random OTs left for the GMW triples."""
    message, rots = chooser_extend(chooser, nonce, total)
    leaves = LeavesBob(
        shape, bob_values, ChooserRots(rots.choices[: shape.rots], rots.keys[: shape.rots])
    )
    triples = ChooserRots(rots.choices[shape.rots :], rots.keys[shape.rots :])
    return message + leaves.corrections(), leaves, triples


def _alice_tables(
    holder: HolderSetup,
    nonce: bytes,
    total: int,
    shape: Shape,
    alice_values: Sequence[Sequence[int]],
    circuit: Circuit,
    wire: bytes,
    split: int,
) -> tuple[bytes, Gmw]:
    """Alice's first step: the OT extension from Bob's message, the leaves' tables and her
    first GMW message."""
    rots = holder_extend(holder, nonce, total, wire[:split])
    leaves = LeavesAlice(
        shape, alice_values, HolderRots(rots.keys0[: shape.rots], rots.keys1[: shape.rots])
    )
    tables, shares = leaves.tables(wire[split:])
    gmw = Gmw(
        circuit,
        alice=True,
        rots=HolderRots(rots.keys0[shape.rots :], rots.keys1[shape.rots :]),
        inputs=_share_bits(shares),
    )
    return tables + gmw.send(), gmw


def _bob_tables(
    leaves: LeavesBob, triples: ChooserRots, circuit: Circuit, wire: bytes, size: int
) -> tuple[bytes, Gmw]:
    """Bob's second step: his shares from Alice's tables, then his first GMW message."""
    shares = leaves.shares(wire[:size])
    gmw = Gmw(circuit, alice=False, rots=triples, inputs=_share_bits(shares))
    gmw.receive(wire[size:])
    return gmw.send(), gmw


def _gmw_rounds(t: Transcript, alice_gmw: Gmw, bob_gmw: Gmw, wire: bytes) -> None:
    """The GMW rounds after Bob's first message ``wire``, until Alice has her outputs."""
    current, other = alice_gmw, bob_gmw
    while not alice_gmw.finished:
        message = wire
        t_account = t.alice if current is alice_gmw else t.bob
        t_account(partial(current.receive, message))
        if alice_gmw.finished:
            break
        wire = t_account(current.send)
        t.send("round", wire, from_alice=current is alice_gmw)
        current, other = other, current
