"""GMW with Beaver triples from random OTs agrees with plain evaluation, on fixed-size messages."""

from __future__ import annotations

import secrets
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.circuits.boolean import Circuit
from protocol.compact.gmw import Gmw, rot_count, rounds
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot.extension import ChooserRots, HolderRots, chooser_extend, holder_extend
from tests.protocol.random_circuits import circuits


def parties(ot_pair: Any, circuit: Circuit, shares: tuple[list[int], list[int]]) -> tuple[Gmw, Gmw]:
    count = max(rot_count(circuit), 1)
    nonce = secrets.token_bytes(32)
    message, bob = chooser_extend(ot_pair.chooser, nonce, count)
    alice = holder_extend(ot_pair.holder, nonce, count, message)
    n = rot_count(circuit)
    return (
        Gmw(
            circuit, alice=True, rots=HolderRots(alice.keys0[:n], alice.keys1[:n]), inputs=shares[0]
        ),
        Gmw(
            circuit, alice=False, rots=ChooserRots(bob.choices[:n], bob.keys[:n]), inputs=shares[1]
        ),
    )


def evaluate(alice: Gmw, bob: Gmw) -> tuple[list[int], list[int]]:
    sender, receiver = alice, bob
    sizes = []
    index = 0
    while not alice.finished:
        data = sender.send()
        assert len(data) == sender.message_size(index)
        sizes.append(len(data))
        receiver.receive(data)
        sender, receiver = receiver, sender
        index += 1
    return alice.outputs(), sizes


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(circuit=circuits(), data=st.data())
def test_matches_plain_evaluation(ot_pair: Any, circuit: Circuit, data: st.DataObject) -> None:
    plain = data.draw(
        st.lists(st.integers(0, 1), min_size=len(circuit.inputs), max_size=len(circuit.inputs))
    )
    mask = [secrets.randbits(1) for _ in plain]
    alice, bob = parties(
        ot_pair, circuit, (mask, [p ^ m for p, m in zip(plain, mask, strict=True)])
    )
    outputs, sizes = evaluate(alice, bob)
    assert outputs == circuit.evaluate(plain)
    assert len(sizes) == len(rounds(circuit.depth))


@pytest.mark.parametrize("depth", range(7))
def test_rounds(depth: int) -> None:
    schedule = rounds(depth)
    assert len(schedule) == (depth + 2 if depth % 2 == 0 else depth + 1)  # last one is Bob's
    assert schedule[0].alice_sends and schedule[-1].outputs and not schedule[-1].alice_sends
    sent: dict[bool, list[int]] = {True: [], False: []}
    for step in schedule:
        sent[step.alice_sends] += list(step.levels)
    assert sent[True] == sent[False] == list(range(1, depth + 1))


def test_message_sizes_do_not_depend_on_inputs(ot_pair: Any) -> None:
    c = Circuit()
    a, b, d = c.input(), c.input(), c.input()
    c.output(c.and_(c.and_(a, b), c.and_(a, d)))
    runs = []
    for plain in ([0, 0, 0], [1, 1, 1], [1, 0, 1]):
        mask = [secrets.randbits(1) for _ in plain]
        alice, bob = parties(ot_pair, c, (mask, [p ^ m for p, m in zip(plain, mask, strict=True)]))
        outputs, sizes = evaluate(alice, bob)
        assert outputs == c.evaluate(plain)
        runs.append(sizes)
    assert runs[0] == runs[1] == runs[2]


def test_strict(ot_pair: Any) -> None:
    c = Circuit()
    a, b = c.input(), c.input()
    c.output(c.and_(a, b))
    alice, bob = parties(ot_pair, c, ([0, 1], [1, 1]))
    with pytest.raises(LocalProtocolError):
        bob.send()
    first = alice.send()
    with pytest.raises(RemoteProtocolError):
        bob.receive(first + b"\x00")
    bob.receive(first)
    with pytest.raises(LocalProtocolError):
        alice.outputs()
    with pytest.raises(LocalProtocolError):
        Gmw(c, alice=True, rots=HolderRots((), ()), inputs=[0, 0])
