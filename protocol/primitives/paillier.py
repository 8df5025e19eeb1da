"""Paillier encryption with g = n + 1 (Paillier 1999; the paper's section III-A).

E(m; r) = (1 + m n) r^n  mod n^2, additively homomorphic:
E(a) * E(b) = E(a + b),  E(a)^k = E(k a).

* The key holder (Bob) decrypts with CRT (as python-paillier does) and makes noise r^n with CRT
  exponentiations modulo p^2 and q^2, about four times faster than the public path.
* Everybody draws noise from a :class:`~protocol.primitives.noise.NoisePool`, so online encryption
is a
  multiplication when noise was precomputed.
* Ciphertexts carry a ``fresh`` flag (as TNO's library does): any homomorphic operation clears
  it and only :meth:`PaillierCiphertext.rerandomize` or encryption sets it.  Serialising a
  ciphertext that is not fresh raises :class:`LocalProtocolError`, so "forgot to re-randomise"
  cannot reach the wire.
* Received ciphertexts are validated: 0 < c < n^2 and gcd(c, n) = 1, else
  :class:`RemoteProtocolError`.
"""

from __future__ import annotations

import gmpy2
from gmpy2 import mpz

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.primitives.noise import NoisePool
from protocol.primitives.params import check_modulus_bits
from protocol.primitives.primes import crt_pair, has_small_factor, random_prime, random_unit
from protocol.wire.encoding import Reader, byte_width, int_to_fixed


class PaillierPublicKey:
    """Public key n; anybody can encrypt and compute on ciphertexts."""

    __slots__ = ("ciphertext_width", "n", "noise_pool", "nsquare", "width")

    def __init__(self, n: int, *, insecure_for_tests: bool = False) -> None:
        self.n = mpz(n)
        check_modulus_bits(self.n.bit_length(), insecure_for_tests)
        self.nsquare = self.n * self.n
        self.width = byte_width(self.n)
        self.ciphertext_width = byte_width(self.nsquare)
        self.noise_pool = NoisePool(self._public_noise)

    def _public_noise(self) -> mpz:
        return gmpy2.powmod(random_unit(self.n), self.n, self.nsquare)

    def encrypt(self, m: int) -> PaillierCiphertext:
        """A fresh encryption of ``m`` (taken modulo n; negative values wrap)."""
        c = ((1 + (mpz(m) % self.n) * self.n) * self.noise_pool.take()) % self.nsquare
        return PaillierCiphertext(self, c, fresh=True)

    def plaintext_shift(self, c: mpz, m: int) -> mpz:
        """c * (1 + m n): adds plaintext ``m`` without touching the noise."""
        return (c * (1 + (mpz(m) % self.n) * self.n)) % self.nsquare

    def ciphertext_from_bytes(self, data: bytes) -> PaillierCiphertext:
        """Decode and validate one received ciphertext (exactly ``ciphertext_width`` bytes)."""
        if len(data) != self.ciphertext_width:
            raise RemoteProtocolError(
                f"Paillier ciphertext must be {self.ciphertext_width} bytes, got {len(data)}"
            )
        c = mpz(int.from_bytes(data, "big"))
        if not 0 < c < self.nsquare or gmpy2.gcd(c, self.n) != 1:
            raise RemoteProtocolError("Paillier ciphertext is not in Z*_{n^2}")
        return PaillierCiphertext(self, c, fresh=False)

    def read_ciphertext(self, reader: Reader) -> PaillierCiphertext:
        return self.ciphertext_from_bytes(reader.take(self.ciphertext_width))

    def to_bytes(self) -> bytes:
        """Fixed-width public key: n in ``width`` bytes."""
        return int_to_fixed(int(self.n), self.width)

    @classmethod
    def from_bytes(cls, data: bytes, *, insecure_for_tests: bool = False) -> PaillierPublicKey:
        """Decode a peer's key: odd, composite, no factor below 2^16, not a square, top byte
        non-zero, at least 2048 bits."""
        if not data or data[0] == 0:
            raise RemoteProtocolError("Paillier modulus must have its top byte set")
        n = mpz(int.from_bytes(data, "big"))
        if n % 2 == 0 or gmpy2.is_prime(n) or gmpy2.is_square(n):
            raise RemoteProtocolError("Paillier modulus is not an odd RSA modulus")
        if has_small_factor(n):
            raise RemoteProtocolError("Paillier modulus has a small factor")
        try:
            return cls(n, insecure_for_tests=insecure_for_tests)
        except LocalProtocolError as exc:
            raise RemoteProtocolError(f"peer's Paillier key refused: {exc}") from exc

    def __eq__(self, other: object) -> bool:
        return isinstance(other, PaillierPublicKey) and self.n == other.n

    def __hash__(self) -> int:
        return hash(("paillier", int(self.n)))


class PaillierPrivateKey:
    """The key holder's (Bob's) key: primes p, q with CRT decryption and CRT noise."""

    __slots__ = (
        "_hp",
        "_hq",
        "_p_inv_q",
        "_q2_inv_p2",
        "p",
        "psquare",
        "public_key",
        "q",
        "qsquare",
    )

    def __init__(self, p: int, q: int, *, insecure_for_tests: bool = False) -> None:
        if p == q:
            raise LocalProtocolError("p and q must differ")
        p, q = (mpz(p), mpz(q)) if p < q else (mpz(q), mpz(p))
        self.p, self.q = p, q
        self.psquare, self.qsquare = p * p, q * q
        self.public_key = PaillierPublicKey(p * q, insecure_for_tests=insecure_for_tests)
        n = self.public_key.n
        if gmpy2.gcd(n, (p - 1) * (q - 1)) != 1:
            raise LocalProtocolError("gcd(n, phi(n)) != 1")
        self._p_inv_q = gmpy2.invert(p, q)
        self._q2_inv_p2 = gmpy2.invert(self.qsquare, self.psquare)
        # h_p = L_p(g^(p-1) mod p^2)^-1 mod p with g = n + 1 (python-paillier's CRT variant).
        self._hp = gmpy2.invert(self._l(gmpy2.powmod(n + 1, p - 1, self.psquare), p), p)
        self._hq = gmpy2.invert(self._l(gmpy2.powmod(n + 1, q - 1, self.qsquare), q), q)
        self.public_key.noise_pool = NoisePool(self._crt_noise)

    @classmethod
    def generate(cls, bits: int = 2048, *, insecure_for_tests: bool = False) -> PaillierPrivateKey:
        """A fresh key pair with an n of exactly ``bits`` bits."""
        check_modulus_bits(bits, insecure_for_tests)
        while True:
            p = random_prime(bits // 2)
            q = random_prime(bits - bits // 2)
            if p != q and (p * q).bit_length() == bits:
                return cls(p, q, insecure_for_tests=insecure_for_tests)

    @staticmethod
    def _l(x: mpz, d: mpz) -> mpz:
        return (x - 1) // d

    def _crt_noise(self) -> mpz:
        """A uniform n-th residue modulo n^2, built from its two CRT halves.

        Modulo p^2 the n-th residues are the subgroup of order p - 1, which is exactly the set
        of p-th powers (gcd(q, p - 1) = 1 for balanced primes); s^p for uniform s is uniform in
        it, and a 1024-bit exponent modulo p^2 costs an eighth of r^n modulo n^2.
        """
        rp = gmpy2.powmod(random_unit(self.psquare), self.p, self.psquare)
        rq = gmpy2.powmod(random_unit(self.qsquare), self.q, self.qsquare)
        return crt_pair(rp, rq, self.psquare, self.qsquare, self._q2_inv_p2)

    def decrypt(self, c: PaillierCiphertext) -> int:
        """Plaintext in [0, n)."""
        if c.key != self.public_key:
            raise LocalProtocolError("ciphertext is under another key")
        mp = (self._l(gmpy2.powmod(c.value, self.p - 1, self.psquare), self.p) * self._hp) % self.p
        mq = (self._l(gmpy2.powmod(c.value, self.q - 1, self.qsquare), self.q) * self._hq) % self.q
        return int(crt_pair(mq, mp, self.q, self.p, self._p_inv_q))

    def decrypt_signed(self, c: PaillierCiphertext) -> int:
        """Plaintext in (-n/2, n/2]."""
        m = self.decrypt(c)
        n = int(self.public_key.n)
        return m - n if m > n // 2 else m


class PaillierCiphertext:
    """An element of Z*_{n^2} with operators: ``a + b``, ``a - b``, ``a + 5``, ``-3 * a``."""

    __slots__ = ("fresh", "key", "value")

    def __init__(self, key: PaillierPublicKey, value: mpz, *, fresh: bool = False) -> None:
        self.key = key
        self.value = value
        self.fresh = fresh

    def _same_key(self, other: PaillierCiphertext) -> None:
        if other.key is not self.key and other.key != self.key:
            raise LocalProtocolError("ciphertexts are under different keys")

    def __add__(self, other: PaillierCiphertext | int) -> PaillierCiphertext:
        if isinstance(other, PaillierCiphertext):
            self._same_key(other)
            return PaillierCiphertext(self.key, (self.value * other.value) % self.key.nsquare)
        return PaillierCiphertext(self.key, self.key.plaintext_shift(self.value, other))

    __radd__ = __add__

    def __neg__(self) -> PaillierCiphertext:
        return PaillierCiphertext(self.key, gmpy2.invert(self.value, self.key.nsquare))

    def __sub__(self, other: PaillierCiphertext | int) -> PaillierCiphertext:
        return self + (-other)

    def __rsub__(self, other: int) -> PaillierCiphertext:
        return (-self) + other

    def __mul__(self, k: int) -> PaillierCiphertext:
        if isinstance(k, PaillierCiphertext):
            raise LocalProtocolError("Paillier cannot multiply two ciphertexts")
        # gmpy2 handles negative exponents by inverting first.
        return PaillierCiphertext(self.key, gmpy2.powmod(self.value, mpz(k), self.key.nsquare))

    __rmul__ = __mul__

    def rerandomize(self) -> PaillierCiphertext:
        """Multiply by fresh noise r^n: same plaintext, uniformly distributed ciphertext."""
        noise = self.key.noise_pool.take()
        return PaillierCiphertext(self.key, (self.value * noise) % self.key.nsquare, fresh=True)

    def to_bytes(self) -> bytes:
        """Fixed-width encoding; refuses a ciphertext that was computed on but not re-randomised."""
        if not self.fresh:
            raise LocalProtocolError("refusing to send a Paillier ciphertext that is not fresh")
        return int_to_fixed(int(self.value), self.key.ciphertext_width)
