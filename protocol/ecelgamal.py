"""Exponential ElGamal on secp256k1, used only for zero tests (the compact bit back-end).

E(m; k) = (k G, m G + k H) with H = x G.  Additively homomorphic in m; the key holder cannot
decrypt in general (that is a discrete log) but tests m = 0 by checking C2 == x C1, which is all
the secure comparison needs (Veugen's step 4).

Two encryption paths:

* **Public** (Alice): fresh k, two multiplications.
* **Key holder, batched** (Bob's bit decompositions): C1_i = HashToPoint(nonce, i) is public
  randomness derived from a 16-byte nonce, and C2_i = m_i G + x C1_i.  Under DDH in the random
  oracle model (G, xG, R_i, xR_i) is indistinguishable from (G, xG, R_i, random), so this is as
  hiding as ordinary ElGamal, and the wire carries 16 + 33 bytes per bit instead of 66.

A lone ciphertext is two compressed points, 66 bytes; the point at infinity is never encoded.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
from collections.abc import Sequence

from coincurve import PublicKey

from . import secp256k1 as ec
from .encoding import Reader
from .errors import LocalProtocolError, RemoteProtocolError

CIPHERTEXT_SIZE = 2 * ec.POINT_SIZE
NONCE_SIZE = 16
TAG_SIZE = 8
TOKEN_SIZE = 32 + TAG_SIZE
_DOMAIN = b"pdc/ec-elgamal/C1/v1"
_TAG_DOMAIN = b"pdc/ec-elgamal/token/v1"


def _tag(c2: ec.Point) -> bytes:
    """First 8 bytes of SHA-256 over the x coordinate of C2 (x of -P equals x of P)."""
    return hashlib.sha256(_TAG_DOMAIN + ec.encode(c2)[1:]).digest()[:TAG_SIZE]


def _random_scalar() -> int:
    return 1 + secrets.randbelow(ec.ORDER - 1)


class ECPublicKey:
    """H = x G.  Encrypt, compute on and re-randomise ciphertexts."""

    __slots__ = ("h",)
    name = "ec-elgamal-secp256k1"
    ciphertext_size = CIPHERTEXT_SIZE
    token_size = TOKEN_SIZE
    plaintext_modulus = ec.ORDER

    def __init__(self, h: PublicKey) -> None:
        self.h = h

    def encrypt(self, m: int) -> ECCiphertext:
        k = _random_scalar()
        return ECCiphertext(self, ec.base_mul(k), ec.add_base(ec.mul(self.h, k), m), fresh=True)

    def constant(self, m: int) -> ECCiphertext:
        """The trivial encryption (infinity, m G): not hiding, never sent as is."""
        return ECCiphertext(self, None, ec.base_mul(m))

    def rerandomize(self, c: ECCiphertext) -> ECCiphertext:
        """Add E(0; k) with fresh k."""
        k = _random_scalar()
        return ECCiphertext(
            self, ec.add(c.c1, ec.base_mul(k)), ec.add(c.c2, ec.mul(self.h, k)), fresh=True
        )

    def blind(self, c: ECCiphertext) -> ECCiphertext:
        """rho * c + E(0; k) with rho uniform in Z_q^*: keeps only whether m = 0."""
        rho, k = _random_scalar(), _random_scalar()
        return ECCiphertext(
            self,
            ec.add(ec.mul(c.c1, rho), ec.base_mul(k)),
            ec.add(ec.mul(c.c2, rho), ec.mul(self.h, k)),
            fresh=True,
        )

    def token(self, c: ECCiphertext) -> bytes:
        """40-byte zero-test token of a blinded ciphertext: x(C1) and a tag of x(C2).

        The key holder lifts x(C1) to either of its two points P = +-C1 and accepts iff the tag
        of x P matches: x(x C1) = x(-x C1), and C2 = +-x C1 for a non-zero plaintext happens
        with negligible probability.  A wrong tag match has probability 2^-64.
        """
        if not c.fresh:
            raise LocalProtocolError("refusing to tokenise an EC ciphertext that is not fresh")
        return ec.encode(c.c1)[1:] + _tag(c.c2)

    def batch_size(self, count: int) -> int:
        return NONCE_SIZE + ec.POINT_SIZE * count

    def read_batch(self, reader: Reader, count: int) -> list[ECCiphertext]:
        """Decode a key holder's batch: nonce, then ``count`` C2 points."""
        nonce = reader.take(NONCE_SIZE)
        return [
            ECCiphertext(self, _batch_c1(nonce, i), ec.decode(reader.take(ec.POINT_SIZE)))
            for i in range(count)
        ]

    def read_ciphertext(self, reader: Reader) -> ECCiphertext:
        c1 = ec.decode(reader.take(ec.POINT_SIZE))
        c2 = ec.decode(reader.take(ec.POINT_SIZE))
        return ECCiphertext(self, c1, c2)

    def ciphertext_from_bytes(self, data: bytes) -> ECCiphertext:
        reader = Reader(data)
        c = self.read_ciphertext(reader)
        reader.finish()
        return c

    def to_bytes(self) -> bytes:
        return ec.encode(self.h)

    @classmethod
    def from_bytes(cls, data: bytes) -> ECPublicKey:
        return cls(ec.decode(data))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ECPublicKey) and self.to_bytes() == other.to_bytes()

    def __hash__(self) -> int:
        return hash(self.to_bytes())


def _batch_c1(nonce: bytes, index: int) -> PublicKey:
    return ec.hash_to_point(_DOMAIN, nonce + index.to_bytes(4, "big"))


class ECPrivateKey:
    """The key holder's scalar x."""

    __slots__ = ("public_key", "x")

    def __init__(self, x: int) -> None:
        if not 0 < x < ec.ORDER:
            raise LocalProtocolError("EC secret out of range")
        self.x = x
        h = ec.base_mul(x)
        assert h is not None
        self.public_key = ECPublicKey(h)

    @classmethod
    def generate(cls) -> ECPrivateKey:
        return cls(_random_scalar())

    def encrypt_batch(self, values: Sequence[int]) -> bytes:
        """Encrypt ``values`` with hash-derived C1 (see the module docstring); wire bytes."""
        nonce = secrets.token_bytes(NONCE_SIZE)
        parts = [nonce]
        for i, m in enumerate(values):
            c2 = ec.add_base(ec.mul(_batch_c1(nonce, i), self.x), m)
            parts.append(ec.encode(c2))
        return b"".join(parts)

    def is_zero(self, c: ECCiphertext) -> bool:
        """m == 0  iff  C2 == x C1."""
        return _point_bytes(c.c2) == _point_bytes(ec.mul(c.c1, self.x))

    def token_is_zero(self, data: bytes) -> bool:
        """Zero test on a token made by :meth:`ECPublicKey.token` (invalid x is refused)."""
        if len(data) != TOKEN_SIZE:
            raise RemoteProtocolError("EC token has the wrong size")
        c1 = ec.decode(b"\x02" + bytes(data[:32]))
        return hmac.compare_digest(_tag(ec.mul(c1, self.x)), bytes(data[32:]))

    def decrypt_small(self, c: ECCiphertext, bound: int) -> int:
        """m for |m| < bound by exhaustive search (tests and diagnostics only)."""
        mg = ec.add(c.c2, ec.neg(ec.mul(c.c1, self.x)))
        for m in range(-bound + 1, bound):
            if _point_bytes(ec.base_mul(m)) == _point_bytes(mg):
                return m
        raise LocalProtocolError("plaintext outside the searched range")


def _point_bytes(p: ec.Point) -> bytes:
    return b"" if p is None else p.format(compressed=True)


class ECCiphertext:
    """(C1, C2) with operators ``a + b``, ``a - b``, ``a + 5``, ``3 * a``, ``-a``."""

    __slots__ = ("c1", "c2", "fresh", "key")

    def __init__(
        self, key: ECPublicKey, c1: ec.Point, c2: ec.Point, *, fresh: bool = False
    ) -> None:
        self.key, self.c1, self.c2, self.fresh = key, c1, c2, fresh

    def __add__(self, other: ECCiphertext | int) -> ECCiphertext:
        if isinstance(other, ECCiphertext):
            return ECCiphertext(self.key, ec.add(self.c1, other.c1), ec.add(self.c2, other.c2))
        return ECCiphertext(self.key, self.c1, ec.add_base(self.c2, other))

    __radd__ = __add__

    def __neg__(self) -> ECCiphertext:
        return ECCiphertext(self.key, ec.neg(self.c1), ec.neg(self.c2))

    def __sub__(self, other: ECCiphertext | int) -> ECCiphertext:
        return self + (-other)

    def __rsub__(self, other: int) -> ECCiphertext:
        return (-self) + other

    def __mul__(self, k: int) -> ECCiphertext:
        if isinstance(k, ECCiphertext):
            raise LocalProtocolError("ElGamal cannot multiply two ciphertexts")
        return ECCiphertext(self.key, ec.mul(self.c1, k), ec.mul(self.c2, k))

    __rmul__ = __mul__

    def to_bytes(self) -> bytes:
        """66 bytes; only fresh (re-randomised) ciphertexts may be sent."""
        if not self.fresh:
            raise LocalProtocolError("refusing to send an EC ciphertext that is not fresh")
        if self.c1 is None or self.c2 is None:
            raise LocalProtocolError("ciphertext contains the point at infinity")
        return ec.encode(self.c1) + ec.encode(self.c2)
