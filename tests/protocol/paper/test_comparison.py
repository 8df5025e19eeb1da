"""Veugen's comparison (paper suite): correct on every boundary, fixed sizes, strict machines."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.errors import InsecureParametersError, LocalProtocolError, RemoteProtocolError
from protocol.paper.comparison import (
    BitDecompositions,
    BlindedTests,
    ComparisonAlice,
    ComparisonBob,
    MaskedDifferences,
    pack_differences,
    slots_per_ciphertext,
)
from protocol.tools.loopback import run_comparison


def parties(
    keys: Any, values: list[int], l: int, thresholds: list[list[int]] | None = None, kappa: int = 40
) -> tuple[ComparisonAlice, ComparisonBob]:
    pub = keys.paillier_pub
    thresholds = thresholds or [[0] for _ in values]
    packed = pack_differences(pub, [pub.encrypt(v) for v in values], l, kappa)
    alice = ComparisonAlice(pub, keys.dgk_pub, l, kappa, packed, thresholds)
    slots = [len(p.constants) for p in packed]
    bob = ComparisonBob(keys.paillier, keys.dgk, l, kappa, slots, [len(t) for t in thresholds])
    return alice, bob


def compare(keys: Any, values: list[int], l: int, thresholds: list[list[int]] | None = None) -> Any:
    alice, bob = parties(keys, values, l, thresholds)
    transcript = run_comparison(alice, bob)
    result = [
        [a ^ b for a, b in zip(pa, pb, strict=True)]
        for pa, pb in zip(alice.shares, bob.shares, strict=True)
    ]
    return result, transcript


def boundary_values(l: int) -> list[int]:
    lo, hi = -(2 ** (l - 1)), 2 ** (l - 1) - 1
    return sorted({v for v in (lo, lo + 1, -2, -1, 0, 1, 2, hi - 1, hi) if lo <= v <= hi})


@pytest.mark.parametrize("l", [1, 2, 20, 42])
def test_every_boundary(keys: Any, l: int) -> None:
    values = boundary_values(l)
    result, _ = compare(keys, values, l)
    assert result == [[int(v >= 0)] for v in values]


@settings(
    max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_random_values_and_thresholds(keys: Any, data: st.DataObject) -> None:
    l = data.draw(st.sampled_from([8, 20, 42]))
    half = 2 ** (l - 2)
    values = data.draw(st.lists(st.integers(-half, half), min_size=1, max_size=12))
    thresholds = [
        data.draw(st.lists(st.integers(-half + 1, half), min_size=1, max_size=2)) for _ in values
    ]
    result, _ = compare(keys, values, l, thresholds)
    assert result == [[int(v >= t) for t in ts] for v, ts in zip(values, thresholds, strict=True)]


def test_batch_spans_several_packed_ciphertexts(keys: Any) -> None:
    l = 20
    per = slots_per_ciphertext(keys.paillier_pub, l, 40)
    values = [(i % 7) - 3 for i in range(2 * per + 3)]
    result, transcript = compare(keys, values, l)
    assert result == [[int(v >= 0)] for v in values]
    assert transcript.sizes[0] == ("masked", 3 * 512)


def test_wire_sizes_are_fixed(keys: Any) -> None:
    l = 42
    _, t1 = compare(keys, [5], l)
    _, t2 = compare(keys, [-(2**41)], l)
    assert t1.sizes == t2.sizes == [("masked", 512), ("bits", 256 * l), ("tests", 256 * (l + 1))]


def test_shares_are_not_the_result(keys: Any) -> None:
    seen_alice, seen_bob = set(), set()
    for _ in range(12):
        alice, bob = parties(keys, [2], 8)
        run_comparison(alice, bob)
        seen_alice.add(alice.shares[0][0])
        seen_bob.add(bob.shares[0][0])
        assert alice.shares[0][0] ^ bob.shares[0][0] == 1
    assert seen_alice == {0, 1} and seen_bob == {0, 1}


def test_steps_out_of_order_are_local_errors(keys: Any) -> None:
    alice, bob = parties(keys, [0, 1], 8)
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


def test_malformed_messages_are_rejected(keys: Any) -> None:
    alice, bob = parties(keys, [0, 1], 8)
    masked = alice.mask()
    with pytest.raises(RemoteProtocolError):
        alice.compare_bits(BitDecompositions(b"\x00" * alice.bits_size()))
    with pytest.raises(RemoteProtocolError):
        bob.decompose(MaskedDifferences(masked.ciphertexts * 2))
    # (values above the slots and tests with several zeros are not refused: a refusal would
    # be a bit of a deviating Alice's choice; tests/protocol/deviating/)


def test_wrong_test_count_is_rejected(keys: Any) -> None:
    alice, bob = parties(keys, [1], 8)
    tests = alice.compare_bits(bob.decompose(alice.mask()))
    with pytest.raises(RemoteProtocolError):
        bob.zero_test(BlindedTests(tests.ciphertexts[:-1]))


def test_parameter_floor(keys: Any) -> None:
    with pytest.raises(InsecureParametersError):
        parties(keys, [1], 8, kappa=20)
    with pytest.raises(LocalProtocolError):
        ComparisonBob(keys.paillier, keys.dgk, 0, 40, [1], [1])
    with pytest.raises(LocalProtocolError):  # DGK's u = 263 carries l <= 86 only
        ComparisonBob(keys.paillier, keys.dgk, 87, 40, [1], [1])
