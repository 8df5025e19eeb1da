"""Homomorphic gates (paper suite) agree with plain evaluation."""

from __future__ import annotations

import secrets
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.circuits.boolean import Circuit
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.paper.hegates import AND, HeGatesAlice, HeGatesBob, bilinear
from tests.protocol.random_circuits import circuits


def test_bilinear_coefficients() -> None:
    for known1 in (0, 1):
        for known2 in (0, 1):
            c, c1, c2, c12 = bilinear(AND, known1, known2)
            for y1 in (0, 1):
                for y2 in (0, 1):
                    assert c + c1 * y1 + c2 * y2 + c12 * y1 * y2 == (known1 ^ y1) & (known2 ^ y2)


def run(keys: Any, circuit: Circuit, plain: list[int]) -> list[int]:
    mask = [secrets.randbits(1) for _ in plain]
    alice = HeGatesAlice(circuit, keys.dgk_pub, mask)
    bob = HeGatesBob(circuit, keys.dgk, [p ^ m for p, m in zip(plain, mask, strict=True)])
    while bob.level < bob.depth:
        bob.finish(alice.evaluate(bob.offer()))
    return alice.open(bob.open())


@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(circuit=circuits(max_gates=15), data=st.data())
def test_matches_plain_evaluation(keys: Any, circuit: Circuit, data: st.DataObject) -> None:
    n = len(circuit.inputs)
    plain = data.draw(st.lists(st.integers(0, 1), min_size=n, max_size=n))
    assert run(keys, circuit, plain) == circuit.evaluate(plain)


def test_strict(keys: Any) -> None:
    c = Circuit()
    a, b = c.input(), c.input()
    c.output(c.and_(a, b))
    alice = HeGatesAlice(c, keys.dgk_pub, [0, 1])
    bob = HeGatesBob(c, keys.dgk, [1, 1])
    with pytest.raises(LocalProtocolError):
        bob.open()
    offer = bob.offer()
    with pytest.raises(RemoteProtocolError):
        alice.evaluate(offer[:-1])
    bob.finish(alice.evaluate(offer))
    with pytest.raises(LocalProtocolError):
        bob.offer()
    with pytest.raises(RemoteProtocolError):
        alice.open(b"\x03")
