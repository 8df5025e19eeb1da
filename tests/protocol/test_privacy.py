"""Bob's view of a comparison is distributed the same for different inputs with the same result.

Bob's view is what he decrypts (the masked differences d_j) and what he zero-tests (which blinded
c values are zero; with DGK he could even decrypt them fully in Z_u).  For two inputs with the same
comparison result we collect many views and run two-sample tests at a false-alarm rate of about
1e-5 each.  A negative control removes Alice's additive mask and must be caught by the same tests,
so these tests can fail.
"""

from __future__ import annotations

import math
import secrets
from collections import Counter
from typing import cast

import pytest

from protocol.paper.comparison import (
    ComparisonAlice,
    ComparisonBob,
    PackedValues,
    pack_differences,
    slot_bits,
    slots_per_ciphertext,
)
from tests.conftest import Keys

L, KAPPA = 16, 40
Z_CRIT = 4.5  # one-sided normal quantile, about 3e-6


def ks_rejects(a: list[float], b: list[float]) -> bool:
    """Two-sample Kolmogorov-Smirnov at alpha = 1e-5."""
    a, b = sorted(a), sorted(b)
    i = j = 0
    d = 0.0
    while i < len(a) and j < len(b):
        if a[i] <= b[j]:
            i += 1
        else:
            j += 1
        d = max(d, abs(i / len(a) - j / len(b)))
    crit = math.sqrt(-math.log(0.5e-5) / 2) * math.sqrt((len(a) + len(b)) / (len(a) * len(b)))
    return d > crit


def chi2_rejects(a: Counter[int], b: Counter[int]) -> bool:
    """Chi-square test of homogeneity, Wilson-Hilferty normal approximation."""
    cats = sorted(set(a) | set(b))
    if len(cats) < 2:
        return False
    na, nb = sum(a.values()), sum(b.values())
    stat = 0.0
    for c in cats:
        total = a[c] + b[c]
        for count, n in ((a[c], na), (b[c], nb)):
            expected = total * n / (na + nb)
            stat += (count - expected) ** 2 / expected
    df = len(cats) - 1
    z: float = ((stat / df) ** (1 / 3) - (1 - 2 / (9 * df))) / math.sqrt(2 / (9 * df))
    return z > Z_CRIT


def bob_view(keys: Keys, diff: int, count: int) -> dict[str, list[float] | Counter[int]]:
    """Run ``count`` comparisons of x - y = diff and record everything Bob can compute."""
    pub = keys.paillier_pub
    packed: list[PackedValues] | int  # reused below for each decrypted packed value
    slots: list[int] | int  # reused below for the slot count of each ciphertext
    packed = pack_differences(pub, [pub.encrypt(diff)] * count, L, KAPPA)
    alice = ComparisonAlice(pub, keys.dgk_pub, L, KAPPA, packed, [[0]] * count)
    slots = [len(p.constants) for p in packed]
    bob = ComparisonBob(keys.paillier, keys.dgk, L, KAPPA, slots, [1] * count)
    masked = alice.mask()
    w = slot_bits(L, KAPPA)
    per = slots_per_ciphertext(keys.paillier.public_key, L, KAPPA)
    d_values: list[int] = []
    for index, ct in enumerate(masked.ciphertexts):
        packed = keys.paillier.decrypt(ct)
        slots = min(per, count - index * per)
        d_values += [(packed >> (w * k)) & ((1 << w) - 1) for k in range(slots)]
    tests = alice.compare_bits(bob.decompose(masked))
    zeros = [keys.dgk.is_zero(c) for c in tests.ciphertexts]
    group = L + 1
    positions: Counter[int] = Counter()
    counts: Counter[int] = Counter()
    for j in range(count):
        block = zeros[j * group : (j + 1) * group]
        counts[sum(block)] += 1
        if any(block):
            positions[block.index(True)] += 1
    view: dict[str, list[float] | Counter[int]] = {
        "d": [d / 2**w for d in d_values],
        "d_low_nibble": Counter(d & 15 for d in d_values),
        "zero_count": counts,
        "zero_position": positions,
    }
    u = keys.dgk.public_key.u
    values = [keys.dgk.decrypt(c) for c in tests.ciphertexts]
    view["nonzero_bins"] = Counter(v * 8 // u for v in values if v)
    return view


def distinguishable(
    v1: dict[str, list[float] | Counter[int]], v2: dict[str, list[float] | Counter[int]]
) -> list[str]:
    failed = []
    for name in v1:
        if isinstance(v1[name], list):
            if ks_rejects(cast(list[float], v1[name]), cast(list[float], v2[name])):
                failed.append(name)
        elif chi2_rejects(cast(Counter[int], v1[name]), cast(Counter[int], v2[name])):
            failed.append(name)
    return failed


@pytest.mark.slow
def test_views_for_same_result_are_indistinguishable(keys: Keys) -> None:
    count = 200
    small = bob_view(keys, 1, count)  # x - y = 1: x >= y
    large = bob_view(keys, 2**L - 1, count)  # x - y = 2^16 - 1: x >= y
    assert distinguishable(small, large) == []
    negative_small = bob_view(keys, -1, count)  # x < y
    negative_large = bob_view(keys, -(2**L) + 1, count)
    assert distinguishable(negative_small, negative_large) == []


@pytest.mark.slow
def test_negative_control_without_mask_is_caught(
    keys: Keys, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With Alice's additive mask r_j removed, Bob's decrypted d_j reveal the input."""
    real = secrets.randbits

    def weak_randbits(k: int) -> int:
        return real(2) if k == L + KAPPA + 1 else real(k)

    monkeypatch.setattr(secrets, "randbits", weak_randbits)
    small = bob_view(keys, 1, 150)
    large = bob_view(keys, 2**L - 1, 150)
    assert "d" in distinguishable(small, large)
