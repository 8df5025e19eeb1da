from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gmpy2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import InsecureParametersError, LocalProtocolError, RemoteProtocolError
from protocol.primitives.paillier import PaillierPrivateKey, PaillierPublicKey
from protocol.wire.encoding import int_to_fixed
from tests.conftest import Keys

BIG = st.integers(min_value=-(2**600), max_value=2**600)
SMALL = st.integers(min_value=-(2**64), max_value=2**64)


def test_key_sizes(keys: Keys) -> None:
    assert keys.paillier.public_key.n.bit_length() == 2048
    assert len(keys.paillier_pub.to_bytes()) == 256
    assert keys.paillier_pub.ciphertext_width == 512


@settings(max_examples=40, deadline=None)
@given(a=BIG, b=BIG, k=SMALL)
def test_homomorphic_identities(keys: Keys, a: int, b: int, k: int) -> None:
    pub, sk = keys.paillier_pub, keys.paillier
    ca, cb = pub.encrypt(a), pub.encrypt(b)
    assert sk.decrypt_signed(ca) == a
    assert sk.decrypt_signed(ca + cb) == a + b
    assert sk.decrypt_signed(ca - cb) == a - b
    assert sk.decrypt_signed(ca + k) == a + k
    assert sk.decrypt_signed(k - ca) == k - a
    assert sk.decrypt_signed(k * ca) == k * a
    assert sk.decrypt_signed(-ca) == -a
    rerandomized = (ca + cb).rerandomize()
    assert rerandomized.fresh and rerandomized.value != (ca + cb).value
    assert sk.decrypt_signed(rerandomized) == a + b


def test_key_holder_encryption_is_crt_noise_and_decrypts(keys: Keys) -> None:
    sk = keys.paillier
    c = sk.public_key.encrypt(12345)
    assert keys.paillier.decrypt(keys.paillier_pub.ciphertext_from_bytes(c.to_bytes())) == 12345


def test_noise_pool_is_used_once_per_value(keys: Keys) -> None:
    pub = PaillierPublicKey.from_bytes(keys.paillier_pub.to_bytes())
    pub.noise_pool.fill(3)
    assert len(pub.noise_pool) == 3
    values = {pub.encrypt(0).value for _ in range(4)}
    assert len(values) == 4 and len(pub.noise_pool) == 0


def test_fresh_flag_guards_the_wire(keys: Keys) -> None:
    c = keys.paillier_pub.encrypt(5)
    c.to_bytes()
    with pytest.raises(LocalProtocolError):
        (c + 1).to_bytes()
    with pytest.raises(LocalProtocolError):
        keys.paillier_pub.ciphertext_from_bytes(c.to_bytes()).to_bytes()
    assert len((c + 1).rerandomize().to_bytes()) == 512


def test_serialisation_round_trip(keys: Keys) -> None:
    c = keys.paillier_pub.encrypt(-77)
    back = keys.paillier_pub.ciphertext_from_bytes(c.to_bytes())
    assert back.value == c.value and keys.paillier.decrypt_signed(back) == -77


@pytest.mark.parametrize(
    "value",
    ["zero", "nsquare", "above", "multiple_of_p", "short", "long"],
)
def test_malformed_ciphertexts_are_rejected(keys: Keys, value: str) -> None:
    pub = keys.paillier_pub
    width = pub.ciphertext_width
    data = {
        "zero": bytes(width),
        "nsquare": int_to_fixed(int(pub.nsquare), width),
        "above": int_to_fixed(int(pub.nsquare) + 5, width),
        "multiple_of_p": int_to_fixed(int(keys.paillier.p) * 7, width),
        "short": b"\x01" * (width - 1),
        "long": b"\x01" * (width + 1),
    }[value]
    with pytest.raises(RemoteProtocolError):
        pub.ciphertext_from_bytes(data)


@pytest.mark.parametrize(
    "modulus",
    [lambda sk: sk.public_key.n + 1, lambda sk: sk.p, lambda sk: sk.p * sk.p],
    ids=["even", "prime", "square"],
)
def test_bad_public_keys_are_rejected(
    keys: Keys, modulus: Callable[[PaillierPrivateKey], int]
) -> None:
    n = int(modulus(keys.paillier))
    with pytest.raises(RemoteProtocolError):
        PaillierPublicKey.from_bytes(n.to_bytes((n.bit_length() + 7) // 8, "big"))


def test_short_modulus_is_refused_unless_test_only(keys: Keys) -> None:
    small = PaillierPrivateKey.generate(512, insecure_for_tests=True)
    with pytest.raises(InsecureParametersError):
        PaillierPublicKey(small.public_key.n)
    with pytest.raises(InsecureParametersError):
        PaillierPrivateKey.generate(1024)
    with pytest.raises(RemoteProtocolError):
        PaillierPublicKey.from_bytes(small.public_key.to_bytes())


def test_ciphertexts_under_different_keys_do_not_mix(keys: Keys) -> None:
    other = PaillierPrivateKey.generate(512, insecure_for_tests=True)
    with pytest.raises(LocalProtocolError):
        keys.paillier_pub.encrypt(1) + other.public_key.encrypt(1)
    with pytest.raises(LocalProtocolError):
        keys.paillier.decrypt(other.public_key.encrypt(1))


def test_generated_primes_are_prime_and_balanced() -> None:
    sk = PaillierPrivateKey.generate(1024, insecure_for_tests=True)
    assert gmpy2.is_prime(sk.p) and gmpy2.is_prime(sk.q)
    assert sk.p.bit_length() == sk.q.bit_length() == 512
    assert sk.public_key.n.bit_length() == 1024


@pytest.fixture(scope="module")
def phe_pair() -> Any:
    """python-paillier (phe, GPLv3) as an independent oracle; imported by tests only."""
    from phe import paillier as phe_paillier

    return phe_paillier.generate_paillier_keypair(n_length=2048)


class TestInteropWithPhe:
    def test_ours_decrypts_with_phe(self, phe_pair: tuple[Any, Any]) -> None:
        phe_pub, phe_priv = phe_pair
        ours = PaillierPublicKey(phe_pub.n)
        for m in (0, 1, 123456789, 2**200):
            assert phe_priv.raw_decrypt(int(ours.encrypt(m).value)) == m

    def test_phe_decrypts_with_ours(self, phe_pair: tuple[Any, Any]) -> None:
        phe_pub, phe_priv = phe_pair
        ours = PaillierPrivateKey(phe_priv.p, phe_priv.q)
        for m in (0, 1, 987654321, 2**300):
            c = ours.public_key.ciphertext_from_bytes(
                int_to_fixed(phe_pub.raw_encrypt(m), ours.public_key.ciphertext_width)
            )
            assert ours.decrypt(c) == m


def test_key_holder_noise_is_an_nth_residue(keys: Keys) -> None:
    """CRT noise must lie in the subgroup of n-th residues: x^lambda = 1 (mod n^2)."""
    sk = keys.paillier
    lam = (sk.p - 1) * (sk.q - 1) // gmpy2.gcd(sk.p - 1, sk.q - 1)
    values = {int(sk.public_key.noise_pool.take()) for _ in range(5)}
    assert len(values) == 5
    for x in values:
        assert gmpy2.powmod(x, lam, sk.public_key.nsquare) == 1
