"""Run both parties of a sub-protocol in one process, through the real byte encoding.

Every message is serialised with ``to_bytes`` and decoded from those bytes by the receiver, so
byte counts are what a radio would carry.  CPU time is charged to the party whose step runs.
Pure: no sockets, no clocks other than the process CPU clock used for accounting.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TypeVar

from .comparison import (
    BitDecompositions,
    BlindedTests,
    ComparisonAlice,
    ComparisonBob,
    MaskedDifferences,
)
from .encoding import Reader
from .gadgets import GateAlice, GateBob, GateInputs, GateOutputs
from .intersection import Alice, Bob
from .paillier import PaillierPublicKey
from .wire import MsgType
from .zerotest import C

T = TypeVar("T")


@dataclass
class Transcript:
    """Bytes and CPU seconds per direction/party, message and round-trip counts."""

    bytes_alice_to_bob: int = 0
    bytes_bob_to_alice: int = 0
    messages: int = 0
    cpu_alice: float = 0.0
    cpu_bob: float = 0.0
    sizes: list[tuple[str, int]] = field(default_factory=list)

    @property
    def round_trips(self) -> float:
        """A round trip is two messages (one each way)."""
        return self.messages / 2

    def send(self, name: str, data: bytes, *, from_alice: bool) -> bytes:
        if from_alice:
            self.bytes_alice_to_bob += len(data)
        else:
            self.bytes_bob_to_alice += len(data)
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
    alice: ComparisonAlice[C],
    bob: ComparisonBob[C],
    bob_paillier_view: PaillierPublicKey,
    transcript: Transcript | None = None,
) -> Transcript:
    """Steps 1-4 of the comparison; ``bob_paillier_view`` decodes Alice's ciphertexts."""
    t = transcript or Transcript()
    wire = t.send("masked", t.alice(lambda: alice.mask().to_bytes()), from_alice=True)
    masked = t.bob(
        lambda: _read_all(
            wire, lambda r: MaskedDifferences.read(r, bob_paillier_view, bob.masked_count())
        )
    )
    wire = t.send("bits", t.bob(lambda: bob.decompose(masked).to_bytes()), from_alice=False)
    bits = t.alice(lambda: _read_all(wire, lambda r: BitDecompositions.read(r, len(wire))))
    wire = t.send("tests", t.alice(lambda: alice.compare_bits(bits).to_bytes()), from_alice=True)
    tests = t.bob(
        lambda: _read_all(
            wire, lambda r: BlindedTests.read(r, bob.bits.public_key, bob.tests_count())
        )
    )
    t.bob(lambda: bob.zero_test(tests))
    return t


def run_gates(
    alice: GateAlice[C], bob: GateBob[C], transcript: Transcript | None = None
) -> tuple[list[int], list[int], Transcript]:
    """One round trip of two-input gates; returns (Alice's shares, Bob's shares, transcript)."""
    t = transcript or Transcript()
    wire = t.send("gate-inputs", t.bob(lambda: bob.offer().to_bytes()), from_alice=False)
    outputs = t.alice(lambda: alice.evaluate(GateInputs(wire)).to_bytes())
    wire = t.send("gate-outputs", outputs, from_alice=True)
    count = len(bob.inputs)
    bob_shares = t.bob(
        lambda: bob.finish(
            _read_all(wire, lambda r: GateOutputs.read(r, bob.bits.public_key, count))
        )
    )
    assert alice.outputs is not None
    return list(alice.outputs), bob_shares, t


def run_paths(alice: Alice, bob: Bob, transcript: Transcript | None = None) -> Transcript:
    """Both parties of the path protocol, frame by frame, until Alice has her answer."""
    t = transcript if transcript is not None else Transcript()
    names = iter(MsgType)
    frame: bytes | None = t.send(next(names).name, t.alice(alice.start), from_alice=True)
    from_alice = True
    while frame is not None:
        receiver = bob if from_alice else alice
        account = t.bob if from_alice else t.alice
        current = frame
        frame = account(partial(receiver.receive, current))
        from_alice = not from_alice
        if frame is not None:
            t.send(next(names).name, frame, from_alice=from_alice)
    return t
