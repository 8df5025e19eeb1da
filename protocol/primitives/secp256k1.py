"""Group operations on secp256k1 through coincurve (libsecp256k1), with the point at infinity.

coincurve's ``PublicKey`` cannot hold the point at infinity, which homomorphic arithmetic can
reach (E(0) with zero randomness, or P + (-P)); here ``None`` stands for it.  Scalar
multiplication uses libsecp256k1's constant-time ``tweak_mul``.  Decoding accepts only the
33-byte compressed form of a point on the curve, or its x alone for a point with an even y
(32 bytes, as BIP 340 encodes keys); secp256k1 has cofactor 1, so on the curve means in the
group.
"""

from __future__ import annotations

import hashlib

from coincurve import PublicKey

from protocol.errors import LocalProtocolError, RemoteProtocolError

ORDER = 0xFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFEBAAEDCE6AF48A03BBFD25E8CD0364141
POINT_SIZE = 33

Point = PublicKey | None


def _scalar(k: int) -> bytes:
    return (k % ORDER).to_bytes(32, "big")


def base_mul(k: int) -> Point:
    """k * G."""
    k %= ORDER
    if k == 0:
        return None
    return PublicKey.from_valid_secret(_scalar(k))


def mul(p: Point, k: int) -> Point:
    """k * P (k taken modulo the group order).

    A zero scalar still costs one multiplication, so the work does not reveal which of a
    party's secret coefficients were zero.
    """
    k %= ORDER
    if p is None:
        return None
    product = p.multiply(_scalar(k if k else 1))
    return product if k else None


def add(p: Point, q: Point) -> Point:
    """P + Q."""
    if p is None:
        return q
    if q is None:
        return p
    try:
        return PublicKey.combine_keys([p, q])
    except ValueError:  # the sum is the point at infinity
        return None


def neg(p: Point) -> Point:
    """-P: flip the parity byte of the compressed encoding."""
    if p is None:
        return None
    raw = p.format(compressed=True)
    return PublicKey(bytes([raw[0] ^ 1]) + raw[1:])


def encode(p: Point) -> bytes:
    """33-byte compressed encoding; the point at infinity has none."""
    if p is None:
        raise LocalProtocolError("the point at infinity has no wire encoding")
    return p.format(compressed=True)


def decode(data: bytes) -> PublicKey:
    """Parse a 33-byte compressed point; anything not on the curve is the sender's fault."""
    if len(data) != POINT_SIZE or data[0] not in (2, 3):
        raise RemoteProtocolError("not a 33-byte compressed secp256k1 point")
    try:
        return PublicKey(bytes(data))
    except (ValueError, TypeError) as exc:
        raise RemoteProtocolError("point is not on secp256k1") from exc


X_SIZE = 32  # a point with an even y, by its x alone (as BIP 340 encodes public keys)


def has_even_y(p: Point) -> bool:
    return p is not None and p.format(compressed=True)[0] == 2


def decode_x(data: bytes) -> PublicKey:
    """The point with even y and this x; anything not on the curve is the sender's fault."""
    if len(data) != X_SIZE:
        raise RemoteProtocolError("not a 32-byte x-only secp256k1 point")
    return decode(b"\x02" + bytes(data))


def hash_to_point(domain: bytes, data: bytes) -> PublicKey:
    """A point nobody knows the discrete log of: try-and-increment on SHA-256 (random oracle).

    About two tries on average: half of all x coordinates lie on the curve.  Used only for public
    randomness, so the data-dependent number of tries leaks nothing.
    """
    for counter in range(256):
        x = hashlib.sha256(domain + data + bytes([counter])).digest()
        try:
            return PublicKey(b"\x02" + x)
        except ValueError:
            continue
    raise LocalProtocolError("hash_to_point failed 256 times")  # probability 2^-256
