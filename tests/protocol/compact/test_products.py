"""OT products: shares of sums of products modulo 2^L."""

from __future__ import annotations

import secrets
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.compact.products import ProductsAlice, ProductsBob, Shape
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot.extension import chooser_extend, holder_extend


def run(
    ot_pair: Any, shape: Shape, values: list[int], multipliers: list[int]
) -> tuple[list[int], int]:
    nonce = secrets.token_bytes(32)
    message, bob_rots = chooser_extend(ot_pair.chooser, nonce, shape.rots)
    alice_rots = holder_extend(ot_pair.holder, nonce, shape.rots, message)
    bob = ProductsBob(shape, values, bob_rots)
    flips = bob.corrections()
    assert len(flips) == shape.correction_size()
    wire, alice_shares = ProductsAlice(shape, multipliers, alice_rots).message(flips)
    assert len(wire) == shape.message_size()
    bob_shares = bob.shares(wire)
    modulus = 1 << shape.modulus_bits
    return [(a + b) % modulus for a, b in zip(alice_shares, bob_shares, strict=True)], len(wire)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_sums_of_products(ot_pair: Any, data: st.DataObject) -> None:
    modulus_bits = data.draw(st.integers(2, 64))
    bits = data.draw(st.lists(st.integers(1, modulus_bits), min_size=1, max_size=4))
    outputs = data.draw(st.integers(1, 4))
    terms = data.draw(
        st.lists(st.tuples(st.integers(0, len(bits) - 1), st.integers(0, outputs - 1)), max_size=8)
    )
    shape = Shape(modulus_bits, tuple(bits), tuple(terms), outputs)
    values = [data.draw(st.integers(0, 2**b - 1)) for b in bits]
    multipliers = [data.draw(st.integers(-(2**40), 2**40)) for _ in terms]
    result, _ = run(ot_pair, shape, values, multipliers)
    expect = [0] * outputs
    for (v, o), x in zip(terms, multipliers, strict=True):
        expect[o] += values[v] * x
    assert result == [e % (1 << modulus_bits) for e in expect]


def test_strict(ot_pair: Any) -> None:
    shape = Shape(8, (3,), ((0, 0),), 1)
    with pytest.raises(LocalProtocolError):
        Shape(8, (3,), ((1, 0),), 1)
    nonce = secrets.token_bytes(32)
    _, bob_rots = chooser_extend(ot_pair.chooser, nonce, 3)
    with pytest.raises(LocalProtocolError):
        ProductsBob(shape, [8], bob_rots)  # does not fit in 3 bits
    bob = ProductsBob(shape, [5], bob_rots)
    with pytest.raises(RemoteProtocolError):
        bob.shares(b"\x00" * (shape.message_size() + 1))
