from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.comparison import (
    BitDecompositions,
    BlindedTests,
    ComparisonAlice,
    ComparisonBob,
    MaskedDifferences,
    State,
    packed_count,
    slots_per_ciphertext,
)
from protocol.errors import InsecureParametersError, LocalProtocolError, RemoteProtocolError
from protocol.loopback import run_comparison

BACKENDS = ["ec", "dgk"]


def compare(keys, backend, pairs, l, kappa=40):
    """Run one batched comparison through the wire; return (a XOR b list, transcript)."""
    bob_bits, alice_bits = keys.backend(backend)
    pub = keys.paillier_pub
    diffs = [pub.encrypt(x) - pub.encrypt(y) for x, y in pairs]
    alice = ComparisonAlice(pub, alice_bits, l, kappa, diffs)
    bob = ComparisonBob(keys.paillier, bob_bits, l, kappa, len(pairs))
    transcript = run_comparison(alice, bob, keys.paillier.public_key)
    return [a ^ b for a, b in zip(alice.shares, bob.shares, strict=True)], transcript


def boundary_pairs(l):
    lo, hi = -(2 ** (l - 1)), 2 ** (l - 1) - 1
    pairs = [(0, 0), (lo, lo), (hi, hi), (lo, hi), (hi, lo), (0, lo), (lo, 0), (0, hi), (hi, 0)]
    for y in (lo + 1, -1, 0, 1, hi - 1):
        pairs += [(y, y), (y + 1, y), (y - 1, y), (y, y + 1), (y, y - 1)]
    return [(x, y) for x, y in pairs if lo <= x <= hi and lo <= y <= hi]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("l", [1, 2, 20, 42])
def test_every_boundary(keys, backend, l):
    pairs = boundary_pairs(l)
    result, _ = compare(keys, backend, pairs, l)
    assert result == [int(x >= y) for x, y in pairs]


@pytest.mark.parametrize("backend", BACKENDS)
@settings(max_examples=8, deadline=None)
@given(data=st.data())
def test_random_values(keys, backend, data):
    l = data.draw(st.sampled_from([8, 20, 42, 64]))
    value = st.integers(min_value=-(2 ** (l - 1)), max_value=2 ** (l - 1) - 1)
    pairs = data.draw(st.lists(st.tuples(value, value), min_size=1, max_size=30))
    result, _ = compare(keys, backend, pairs, l)
    assert result == [int(x >= y) for x, y in pairs]


def test_batch_spans_several_packed_ciphertexts(keys):
    l = 20
    per = slots_per_ciphertext(keys.paillier_pub, l, 40)
    count = 2 * per + 3
    pairs = [(i % 7 - 3, (i * 5) % 9 - 4) for i in range(count)]
    result, transcript = compare(keys, "ec", pairs, l)
    assert result == [int(x >= y) for x, y in pairs]
    assert transcript.sizes[0] == ("masked", 3 * 512)
    assert packed_count(keys.paillier_pub, l, 40, count) == 3


@pytest.mark.parametrize("backend", BACKENDS)
def test_wire_sizes_are_fixed(keys, backend):
    l = 42
    _, t1 = compare(keys, backend, [(5, 4)], l)
    _, t2 = compare(keys, backend, [(-(2**41), 2**41 - 1)], l)
    assert t1.sizes == t2.sizes
    bits = 16 + 33 * l if backend == "ec" else 256 * l
    tests = 66 * (l + 1) if backend == "ec" else 256 * (l + 1)
    assert t1.sizes == [("masked", 512), ("bits", bits), ("tests", tests)]
    assert t1.messages == 3


def test_shares_are_not_the_result(keys):
    """Neither party's share alone equals the result on every run (they are masked)."""
    seen_alice, seen_bob = set(), set()
    for _ in range(12):
        bob_bits, alice_bits = keys.backend("ec")
        pub = keys.paillier_pub
        alice = ComparisonAlice(pub, alice_bits, 8, 40, [pub.encrypt(3) - pub.encrypt(1)])
        bob = ComparisonBob(keys.paillier, bob_bits, 8, 40, 1)
        run_comparison(alice, bob, keys.paillier.public_key)
        seen_alice.add(alice.shares[0])
        seen_bob.add(bob.shares[0])
        assert alice.shares[0] ^ bob.shares[0] == 1
    assert seen_alice == {0, 1} and seen_bob == {0, 1}


def _parties(keys, count=2, l=8):
    bob_bits, alice_bits = keys.backend("ec")
    pub = keys.paillier_pub
    alice = ComparisonAlice(pub, alice_bits, l, 40, [pub.encrypt(i) for i in range(count)])
    bob = ComparisonBob(keys.paillier, bob_bits, l, 40, count)
    return alice, bob


def test_steps_out_of_order_are_local_errors(keys):
    alice, bob = _parties(keys)
    with pytest.raises(LocalProtocolError):
        _ = alice.shares
    with pytest.raises(LocalProtocolError):
        alice.compare_bits(BitDecompositions(b""))
    masked = alice.mask()
    with pytest.raises(LocalProtocolError):
        alice.mask()
    with pytest.raises(LocalProtocolError):
        bob.zero_test(BlindedTests(()))
    bob.decompose(masked)
    with pytest.raises(LocalProtocolError):
        bob.decompose(masked)


def test_malformed_messages_fail_the_state_machine(keys):
    alice, bob = _parties(keys)
    alice.mask()
    with pytest.raises(RemoteProtocolError):
        alice.compare_bits(BitDecompositions(b"\x00" * alice.bits_size()))
    assert alice.state is State.FAILED
    with pytest.raises(LocalProtocolError):
        alice.compare_bits(BitDecompositions(b""))

    alice, bob = _parties(keys)
    masked = alice.mask()
    with pytest.raises(RemoteProtocolError):
        bob.decompose(MaskedDifferences(masked.ciphertexts * 2))
    assert bob.state is State.FAILED


def test_out_of_range_packing_is_rejected(keys):
    _, bob = _parties(keys, count=1)
    bogus = keys.paillier_pub.encrypt(1 << 200)
    with pytest.raises(RemoteProtocolError):
        bob.decompose(MaskedDifferences((bogus,)))
    assert bob.state is State.FAILED


def test_wrong_test_count_and_double_zero_are_rejected(keys):
    alice, bob = _parties(keys, count=1)
    bits = bob.decompose(alice.mask())
    tests = alice.compare_bits(bits)
    with pytest.raises(RemoteProtocolError):
        bob.zero_test(BlindedTests(tests.ciphertexts[:-1]))

    alice, bob = _parties(keys, count=1)
    bob.decompose(alice.mask())
    zero = keys.ec_pub.encrypt(0)
    with pytest.raises(RemoteProtocolError):
        bob.zero_test(BlindedTests((zero,) * (bob.l + 1)))


def test_parameter_floor(keys):
    bob_bits, alice_bits = keys.backend("ec")
    with pytest.raises(InsecureParametersError):
        ComparisonAlice(keys.paillier_pub, alice_bits, 8, 20, [keys.paillier_pub.encrypt(1)])
    with pytest.raises(LocalProtocolError):
        ComparisonBob(keys.paillier, bob_bits, 0, 40, 1)
    with pytest.raises(LocalProtocolError):  # DGK's u = 197 carries l <= 64 only
        ComparisonBob(keys.paillier, keys.dgk, 65, 40, 1)
