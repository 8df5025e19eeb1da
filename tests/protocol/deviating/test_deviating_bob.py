"""A deviating Bob's keys (paper suite): a modulus with a factor he knows the order of lets
what he decrypts depend on Alice's secrets (her masks multiplied into his ciphertexts).  The
decoders refuse a modulus with a factor below 2^16 -- the cheap case, n = 3 * P; two large
factors of a bad form need a proof of the modulus, which the paper suite does not carry: the
companion runs it only with drones whose operator vouches for their keys
(tests/companion/attacks/test_deviating_peer.py, docs/security.md)."""

from __future__ import annotations

from typing import Any

import pytest

from protocol.dgk import DGKPublicKey
from protocol.encoding import int_to_fixed
from protocol.errors import RemoteProtocolError
from protocol.paillier import PaillierPublicKey
from protocol.primes import has_small_factor, random_prime

pytestmark = pytest.mark.deviating


@pytest.fixture(scope="module")
def three_p() -> int:
    """n = 3 P, 2048 bits (P has its top two bits set): an odd composite, not a square."""
    n = 3 * int(random_prime(2046))
    assert n.bit_length() == 2048
    return n


def test_a_paillier_modulus_with_a_small_factor_is_refused(three_p: int, keys: Any) -> None:
    with pytest.raises(RemoteProtocolError, match="small factor"):
        PaillierPublicKey.from_bytes(int_to_fixed(three_p, 256))
    honest = keys.paillier_pub.to_bytes()  # an honest key still decodes
    assert PaillierPublicKey.from_bytes(honest) == keys.paillier_pub


def test_a_dgk_modulus_with_a_small_factor_is_refused(three_p: int, keys: Any) -> None:
    honest = keys.dgk_pub
    width = honest.width
    forged = b"".join(
        [
            int_to_fixed(three_p, width),
            int_to_fixed(5, width),  # units modulo 3 P
            int_to_fixed(7, width),
            int_to_fixed(honest.u, 2),
            int_to_fixed(honest.t, 2),
        ]
    )
    with pytest.raises(RemoteProtocolError, match="malformed"):
        DGKPublicKey.from_bytes(forged)
    assert DGKPublicKey.from_bytes(honest.to_bytes()).n == honest.n


def test_the_check_sees_every_small_prime_and_no_large_one() -> None:
    big = int(random_prime(512)) * int(random_prime(512))
    assert not has_small_factor(big)
    for p in (3, 5, 65521):  # 65521: the largest prime below 2^16
        assert has_small_factor(p * big)
    assert not has_small_factor(65537 * big)  # the first prime above the bound
