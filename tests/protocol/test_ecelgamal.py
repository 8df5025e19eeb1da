from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import secp256k1 as ec
from protocol.ecelgamal import CIPHERTEXT_SIZE, ECPrivateKey, ECPublicKey
from protocol.encoding import Reader
from protocol.errors import LocalProtocolError, RemoteProtocolError

SMALL = st.integers(min_value=-20, max_value=20)


@settings(max_examples=40, deadline=None)
@given(a=SMALL, b=SMALL, k=st.integers(min_value=-5, max_value=5))
def test_homomorphic_identities(keys, a, b, k):
    pub, sk = keys.ec_pub, keys.ec
    ca, cb = pub.encrypt(a), pub.encrypt(b)
    assert sk.decrypt_small(ca, 200) == a
    assert sk.decrypt_small(ca + cb, 200) == a + b
    assert sk.decrypt_small(ca - cb, 200) == a - b
    assert sk.decrypt_small(k - ca, 200) == k - a
    assert sk.decrypt_small(k * ca, 200) == k * a
    assert sk.decrypt_small(pub.rerandomize(ca), 200) == a
    assert sk.is_zero(ca - a) and sk.is_zero(pub.blind(ca - a))
    assert sk.is_zero(pub.blind(ca)) == (a == 0)


def test_trivial_constant_and_infinity_arithmetic(keys):
    pub, sk = keys.ec_pub, keys.ec
    zero = pub.constant(0)
    assert zero.c1 is None and zero.c2 is None
    c = pub.encrypt(4)
    assert sk.decrypt_small(zero + c, 10) == 4
    assert sk.is_zero(c - c) and (c - c).c1 is None
    assert sk.decrypt_small(pub.rerandomize(pub.constant(3)), 10) == 3
    with pytest.raises(LocalProtocolError):
        pub.constant(3).to_bytes()


def test_batch_encryption_uses_hashed_c1_and_is_compact(keys):
    data = keys.ec.encrypt_batch([1, 0, 1])
    assert len(data) == 16 + 3 * 33 == keys.ec_pub.batch_size(3)
    cts = keys.ec_pub.read_batch(Reader(data), 3)
    assert [keys.ec.decrypt_small(c, 3) for c in cts] == [1, 0, 1]
    again = keys.ec.encrypt_batch([1, 0, 1])
    assert again[:16] != data[:16] and again[16:] != data[16:]


def test_ciphertext_encoding(keys):
    c = keys.ec_pub.encrypt(9)
    data = c.to_bytes()
    assert len(data) == CIPHERTEXT_SIZE == 66
    assert keys.ec.decrypt_small(keys.ec_pub.ciphertext_from_bytes(data), 20) == 9
    with pytest.raises(LocalProtocolError):
        (c + 1).to_bytes()


def _not_on_curve() -> bytes:
    for x in range(1, 100):
        candidate = b"\x02" + x.to_bytes(32, "big")
        try:
            ec.decode(candidate)
        except RemoteProtocolError:
            return candidate
    raise AssertionError("no invalid x found")


@pytest.mark.parametrize("case", ["prefix", "not_on_curve", "short", "long", "x_too_big"])
def test_invalid_points_are_rejected(keys, case):
    good = keys.ec_pub.encrypt(1).to_bytes()
    data = {
        "prefix": b"\x04" + good[1:],
        "not_on_curve": _not_on_curve() + good[33:],
        "short": good[:-1],
        "long": good + b"\x00",
        "x_too_big": b"\x02" + b"\xff" * 32 + good[33:],
    }[case]
    with pytest.raises(RemoteProtocolError):
        keys.ec_pub.ciphertext_from_bytes(data)
    key_bytes = {"short": data[:32], "long": data[:33] + b"\x00"}.get(case, data[:33])
    with pytest.raises(RemoteProtocolError):
        ECPublicKey.from_bytes(key_bytes)


def test_point_helpers():
    g = ec.base_mul(1)
    assert ec.add(g, ec.neg(g)) is None
    assert ec.mul(g, ec.ORDER) is None and ec.mul(None, 5) is None
    assert ec.add_base(ec.neg(g), 1) is None
    assert ec.encode(ec.mul(g, 7)) == ec.encode(ec.base_mul(7))
    with pytest.raises(LocalProtocolError):
        ec.encode(None)


def test_secret_range():
    with pytest.raises(LocalProtocolError):
        ECPrivateKey(0)
    with pytest.raises(LocalProtocolError):
        ECPrivateKey(ec.ORDER)
