from __future__ import annotations

import gmpy2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import InsecureParametersError, LocalProtocolError, RemoteProtocolError
from protocol.primitives.dgk import DGKPrivateKey, DGKPublicKey, u_for_bits
from protocol.wire.encoding import int_to_fixed
from tests.conftest import Keys

SMALL = st.integers(min_value=-1000, max_value=1000)


def test_key_structure_follows_the_2009_correction(keys: Keys) -> None:
    sk = keys.dgk
    u = sk.public_key.u
    assert sk.public_key.n.bit_length() == 2048 and sk.public_key.t == 224
    assert sk.vp.bit_length() == sk.vq.bit_length() == 224 and sk.vp != sk.vq
    assert gmpy2.is_prime(u) and gmpy2.is_prime(sk.vp) and gmpy2.is_prime(sk.vq)
    assert (sk.p - 1) % (u * sk.vp) == 0 and (sk.q - 1) % (u * sk.vq) == 0
    assert (sk.q - 1) % sk.vp != 0 and (sk.p - 1) % sk.vq != 0
    g, h, n = sk.public_key.g, sk.public_key.h, sk.public_key.n
    assert gmpy2.powmod(g, u * sk.vp * sk.vq, n) == 1
    assert gmpy2.powmod(g, sk.vp * sk.vq, n) != 1
    assert gmpy2.powmod(h, sk.vp * sk.vq, n) == 1 and gmpy2.powmod(h, sk.vp, n) != 1


def test_u_follows_comparison_bits() -> None:
    assert u_for_bits(42) == 131
    assert gmpy2.is_prime(u_for_bits(64)) and u_for_bits(64) > 3 * 64 + 3


@settings(max_examples=30, deadline=None)
@given(a=SMALL, b=SMALL, k=SMALL)
def test_homomorphic_identities(keys: Keys, a: int, b: int, k: int) -> None:
    pub, sk = keys.dgk_pub, keys.dgk
    u = pub.u
    ca, cb = pub.encrypt(a), pub.encrypt(b)
    assert sk.decrypt(ca) == a % u
    assert sk.decrypt(ca + cb) == (a + b) % u
    assert sk.decrypt(ca - cb) == (a - b) % u
    assert sk.decrypt(k - ca) == (k - a) % u
    assert sk.decrypt(k * ca) == (k * a) % u
    assert sk.is_zero(ca - a) and sk.is_zero(pub.blind(ca - a))
    assert sk.is_zero(pub.blind(ca)) == (a % u == 0)
    assert sk.decrypt(pub.rerandomize(ca)) == a % u


def test_key_holder_batch_is_fresh_and_decodes(keys: Keys) -> None:
    data = keys.dgk.encrypt_batch([0, 1, 1, 0])
    assert len(data) == 4 * 256
    from protocol.wire.encoding import Reader

    cts = keys.dgk_pub.read_batch(Reader(data), 4)
    assert [keys.dgk.decrypt(c) for c in cts] == [0, 1, 1, 0]


def test_public_key_round_trip(keys: Keys) -> None:
    data = keys.dgk.public_key.to_bytes()
    assert DGKPublicKey.from_bytes(data) == keys.dgk.public_key
    assert len(data) == 3 * 256 + 4


@pytest.mark.parametrize("case", ["zero", "n", "factor", "short"])
def test_malformed_ciphertexts_are_rejected(keys: Keys, case: str) -> None:
    pub = keys.dgk_pub
    data = {
        "zero": bytes(256),
        "n": int_to_fixed(int(pub.n), 256),
        "factor": int_to_fixed(int(keys.dgk.p), 256),
        "short": b"\x05" * 255,
    }[case]
    with pytest.raises(RemoteProtocolError):
        pub.ciphertext_from_bytes(data)


@pytest.mark.parametrize("case", ["u_not_prime", "u_huge", "g_zero", "t_small", "truncated"])
def test_bad_public_keys_are_rejected(keys: Keys, case: str) -> None:
    data = bytearray(keys.dgk.public_key.to_bytes())
    if case == "u_not_prime":
        data[-4:-2] = (133).to_bytes(2, "big")
    elif case == "u_huge":
        data[-4:-2] = (65521).to_bytes(2, "big")
        data = data[:-4] + (65521).to_bytes(2, "big") + (224).to_bytes(2, "big")
        data = bytearray(data)
        data += b"\x00"  # also breaks the length
    elif case == "g_zero":
        data[256:512] = bytes(256)
    elif case == "t_small":
        data[-2:] = (160).to_bytes(2, "big")
    elif case == "truncated":
        data = data[:-1]
    with pytest.raises(RemoteProtocolError):
        DGKPublicKey.from_bytes(bytes(data))


def test_weak_parameters_are_refused() -> None:
    with pytest.raises(InsecureParametersError):
        DGKPrivateKey.generate(t=160)
    with pytest.raises(InsecureParametersError):
        DGKPrivateKey.generate(bits=1024)
    sk = DGKPrivateKey.generate(bits=512, t=64, insecure_for_tests=True)
    assert sk.decrypt(sk.public_key.encrypt(7)) == 7


def test_unfresh_ciphertext_cannot_be_sent(keys: Keys) -> None:
    with pytest.raises(LocalProtocolError):
        (keys.dgk_pub.encrypt(1) + 1).to_bytes()
