from __future__ import annotations

import itertools

import pytest

from protocol.encoding import Reader
from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.gadgets import (
    AND,
    OR,
    XOR,
    GateAlice,
    GateBob,
    GateOutputs,
    OpenedShares,
    not_share,
    xor_shares,
)
from protocol.loopback import run_gates

ALL_SHARES = list(itertools.product((0, 1), repeat=4))  # a1, b1, a2, b2


def test_local_gadgets_on_all_inputs():
    for a1, b1, a2, b2 in ALL_SHARES:
        x1, x2 = a1 ^ b1, a2 ^ b2
        assert not_share(a1, alice=True) ^ not_share(b1, alice=False) == 1 - x1
        assert xor_shares(a1, a2) ^ xor_shares(b1, b2) == x1 ^ x2


@pytest.mark.parametrize("backend", ["ec", "dgk"])
@pytest.mark.parametrize("table", [AND, OR, XOR], ids=["and", "or", "xor"])
def test_two_input_gates_on_all_share_combinations(keys, backend, table):
    bob_bits, alice_bits = keys.backend(backend)
    cases = ALL_SHARES * 2  # each combination twice, with fresh masks
    alice = GateAlice(alice_bits, [(a1, a2) for a1, _, a2, _ in cases], [table] * len(cases))
    bob = GateBob(bob_bits, [(b1, b2) for _, b1, _, b2 in cases])
    a_out, b_out, transcript = run_gates(alice, bob)
    for (a1, b1, a2, b2), a, b in zip(cases, a_out, b_out, strict=True):
        assert a ^ b == table[2 * (a1 ^ b1) + (a2 ^ b2)]
    assert transcript.messages == 2
    assert set(a_out) == {0, 1}  # output shares are masked, not the plain result


def test_gate_errors(keys):
    with pytest.raises(LocalProtocolError):
        GateBob(keys.ec, [(0, 2)])
    with pytest.raises(LocalProtocolError):
        GateAlice(keys.ec_pub, [(0, 1)], [])
    bob = GateBob(keys.ec, [(0, 1)])
    with pytest.raises(RemoteProtocolError):
        bob.finish(GateOutputs(()))
    alice = GateAlice(keys.ec_pub, [(0, 1)], [AND])
    with pytest.raises(RemoteProtocolError):
        from protocol.gadgets import GateInputs

        alice.evaluate(GateInputs(b"\x00" * 10))
    with pytest.raises(RemoteProtocolError):
        GateOutputs.read(Reader(b"\x02" * 65), keys.ec_pub, 1)


def test_open_to_alice():
    alice, bob = [1, 0, 1, 1, 0, 0, 1, 0, 1], [0, 0, 1, 0, 1, 0, 1, 1, 1]
    msg = OpenedShares.from_shares(bob)
    assert len(msg.to_bytes()) == 2
    decoded = OpenedShares.read(Reader(msg.to_bytes()), len(bob))
    assert decoded.open(alice) == [a ^ b for a, b in zip(alice, bob, strict=True)]
    with pytest.raises(RemoteProtocolError):
        OpenedShares.read(Reader(b"\xff\xff"), 9)
    with pytest.raises(LocalProtocolError):
        decoded.open([0])
