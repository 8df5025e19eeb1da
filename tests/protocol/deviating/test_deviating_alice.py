"""A deviating Alice against Bob's side of the paper suite's comparison: what Bob does next
must not depend on his values through anything but the protocol's output.

Bob used to refuse (a one-byte abort Alice sees) a masked value above its slots and a zero
test with more than one zero.  Alice chooses what those messages encrypt -- any linear form
of Bob's encrypted values, plus what she likes -- so each refusal was one bit of her choice
about Bob's path per run, beyond the output.  Now Bob reads only the slots and counts any
zero once: his reply is the same, whatever she sent.
"""

from __future__ import annotations

import copy
from typing import Any

import pytest

from protocol.paper.comparison import BlindedTests, ComparisonAlice, ComparisonBob, pack_differences

pytestmark = pytest.mark.deviating

L, KAPPA = 8, 40


def _bob(keys: Any, count: int = 1) -> ComparisonBob:
    return ComparisonBob(keys.paillier, keys.dgk, L, KAPPA, [count], [1] * count)


def _honest_alice(keys: Any, values: list[int]) -> ComparisonAlice:
    pub = keys.paillier_pub
    packed = pack_differences(pub, [pub.encrypt(v) for v in values], L, KAPPA)
    return ComparisonAlice(pub, keys.dgk_pub, L, KAPPA, packed, [[0] for _ in values])


@pytest.mark.parametrize("bob_value", [3, 200])
def test_an_overflowing_linear_form_of_bobs_value_is_not_refused(keys: Any, bob_value: int) -> None:
    """Alice sends, instead of her masked value, E(2^k * v + r) for Bob's v: whether it
    overflows Bob's slot depends on v.  Bob answers in full either way, the same size."""
    pub = keys.paillier_pub
    alice = _honest_alice(keys, [0])
    honest = alice.mask()
    bob = _bob(keys)
    encrypted_v = pub.encrypt(bob_value)  # what Alice holds of Bob's: his ciphertext
    probe = (encrypted_v * (1 << 45) + 12345).rerandomize()  # v * 2^45 + r
    reply = bob.decompose(type(honest)((probe,)))
    assert len(reply.to_bytes()) == alice.bits_size()


def test_tests_with_several_zeros_are_not_refused(keys: Any) -> None:
    """Alice puts two, or every, zero in a comparison's tests: Bob takes any zero once, his
    share is what one zero gives, and nothing is refused."""
    dgk = keys.dgk_pub
    decomposed = _bob(keys)
    decomposed.decompose(_honest_alice(keys, [5]).mask())
    shares = {}
    for zeros in (1, 2, L + 1):
        bob = copy.copy(decomposed)  # the same Bob, at the same step, for each variant
        tests = [dgk.encrypt(0) for _ in range(zeros)] + [
            dgk.encrypt(1) for _ in range(L + 1 - zeros)
        ]
        bob.zero_test(BlindedTests(tuple(tests)))
        shares[zeros] = bob.shares
    assert shares[1] == shares[2] == shares[L + 1]
