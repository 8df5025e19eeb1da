"""DGK encryption (Damgard, Geisler, Kroigaard 2007, with the 2009 correction).

n = p q with u | p-1, u | q-1 (u a small prime: the plaintext space is Z_u), v_p | p-1 and
v_q | q-1 (t-bit primes, v_p != v_q, v_p not dividing q-1, v_q not dividing p-1).  g has order
u v_p v_q and h has order v_p v_q in Z_n^*.

E(m; r) = g^m h^r mod n with r of 2.5 t bits.  The key holder tests m = 0 (mod u) by
c^(v_p) mod p == 1, since h^(v_p) = 1 (mod p) and g has order u v_p modulo p.  That zero test is
all the secure comparison needs; full decryption of a small u is provided for tests.

u is chosen from the comparison bit length l: the smallest prime above 3 l + 3, the largest
|c_i| of Veugen's comparison, so blinding by rho in Z_u^* keeps non-zero values non-zero and
uniform.  t >= 224 by default (a known attack runs in about 2^(t/2)).
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence

import gmpy2
from gmpy2 import mpz

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.primitives.noise import NoisePool
from protocol.primitives.params import check_dgk_t, check_modulus_bits
from protocol.primitives.primes import (
    crt_pair,
    has_small_factor,
    is_probable_prime,
    random_prime,
    random_unit,
)
from protocol.wire.encoding import Reader, byte_width, int_to_fixed

MAX_U_BITS = 16


def u_for_bits(l: int) -> int:
    """The plaintext prime for l-bit comparisons: smallest prime > 3 l + 3."""
    return int(gmpy2.next_prime(3 * l + 3))


class DGKPublicKey:
    """(n, g, h, u, t); anybody can encrypt and compute on ciphertexts modulo n."""

    __slots__ = ("_g_powers", "g", "h", "n", "noise_pool", "t", "u", "width")
    name = "dgk"

    def __init__(
        self, n: int, g: int, h: int, u: int, t: int, *, insecure_for_tests: bool = False
    ) -> None:
        self.n, self.g, self.h = mpz(n), mpz(g), mpz(h)
        self.u, self.t = int(u), int(t)
        check_modulus_bits(self.n.bit_length(), insecure_for_tests)
        check_dgk_t(self.t, insecure_for_tests)
        self.width = byte_width(self.n)
        self._g_powers = [gmpy2.powmod(self.g, m, self.n) for m in range(self.u)]
        self.noise_pool = NoisePool(self._public_noise)

    @property
    def plaintext_modulus(self) -> int:
        return self.u

    def _public_noise(self) -> mpz:
        return gmpy2.powmod(self.h, mpz(secrets.randbits(self.t * 5 // 2)), self.n)

    def g_pow(self, m: int) -> mpz:
        return self._g_powers[m % self.u]

    def encrypt(self, m: int) -> DGKCiphertext:
        return DGKCiphertext(self, (self.g_pow(m) * self.noise_pool.take()) % self.n, fresh=True)

    def constant(self, m: int) -> DGKCiphertext:
        """The trivial encryption g^m: not hiding, never sent as is."""
        return DGKCiphertext(self, self.g_pow(m))

    def rerandomize(self, c: DGKCiphertext) -> DGKCiphertext:
        return DGKCiphertext(self, (c.value * self.noise_pool.take()) % self.n, fresh=True)

    def blind(self, c: DGKCiphertext) -> DGKCiphertext:
        """c^rho * h^r with rho uniform in Z_u^*: keeps only whether m = 0."""
        rho = 1 + secrets.randbelow(self.u - 1)
        value = (gmpy2.powmod(c.value, rho, self.n) * self.noise_pool.take()) % self.n
        return DGKCiphertext(self, value, fresh=True)

    def token(self, c: DGKCiphertext) -> bytes:
        """A DGK zero-test token is the ciphertext itself."""
        return c.to_bytes()

    def batch_size(self, count: int) -> int:
        return self.width * count

    def read_ciphertext(self, reader: Reader) -> DGKCiphertext:
        c = mpz(reader.uint(self.width))
        if not 0 < c < self.n or gmpy2.gcd(c, self.n) != 1:
            raise RemoteProtocolError("DGK ciphertext is not in Z*_n")
        return DGKCiphertext(self, c)

    def read_batch(self, reader: Reader, count: int) -> list[DGKCiphertext]:
        return [self.read_ciphertext(reader) for _ in range(count)]

    def ciphertext_from_bytes(self, data: bytes) -> DGKCiphertext:
        reader = Reader(data)
        c = self.read_ciphertext(reader)
        reader.finish()
        return c

    def to_bytes(self) -> bytes:
        """n, g, h (width bytes each), u (2 bytes), t (2 bytes)."""
        return b"".join(
            [
                int_to_fixed(int(self.n), self.width),
                int_to_fixed(int(self.g), self.width),
                int_to_fixed(int(self.h), self.width),
                int_to_fixed(self.u, 2),
                int_to_fixed(self.t, 2),
            ]
        )

    @classmethod
    def from_bytes(cls, data: bytes, *, insecure_for_tests: bool = False) -> DGKPublicKey:
        """Decode and check a peer's key (sizes, ranges, u prime, units)."""
        if (len(data) - 4) % 3 or len(data) < 7:
            raise RemoteProtocolError("DGK public key has a wrong length")
        width = (len(data) - 4) // 3
        reader = Reader(data)
        n, g, h = (mpz(reader.uint(width)) for _ in range(3))
        u, t = reader.uint(2), reader.uint(2)
        reader.finish()
        if byte_width(n) != width or n % 2 == 0 or gmpy2.is_prime(n) or has_small_factor(n):
            raise RemoteProtocolError("DGK modulus is malformed")
        if not is_probable_prime(u) or u.bit_length() > MAX_U_BITS or u < 5:
            raise RemoteProtocolError("DGK u must be a small prime")
        for x in (g, h):
            if not 1 < x < n or gmpy2.gcd(x, n) != 1:
                raise RemoteProtocolError("DGK generator is not a unit modulo n")
        try:
            return cls(n, g, h, u, t, insecure_for_tests=insecure_for_tests)
        except LocalProtocolError as exc:
            raise RemoteProtocolError(f"peer's DGK key refused: {exc}") from exc

    def __eq__(self, other: object) -> bool:
        return isinstance(other, DGKPublicKey) and self.to_bytes() == other.to_bytes()

    def __hash__(self) -> int:
        return hash(self.to_bytes())


def _dgk_prime(bits: int, u: int, v: mpz) -> mpz:
    """A prime p = 2 u v a + 1 in [sqrt(2) 2^(bits-1), 2^bits) for a uniform cofactor a.

    The lower bound makes the product of two such primes exactly ``2 * bits`` long.
    """
    step = 2 * u * v
    low = (gmpy2.isqrt(mpz(1) << (2 * bits - 1)) + 1 + step - 1) // step
    high = ((mpz(1) << bits) - 2) // step
    while True:
        p = step * (low + mpz(secrets.randbelow(int(high - low)))) + 1
        if is_probable_prime(p):
            return p


def _element_of_order(p: mpz, order_factors: tuple[int, ...]) -> mpz:
    """An element of Z_p^* whose order is exactly the product of the distinct primes given."""
    order = 1
    for f in order_factors:
        order *= f
    while True:
        x = gmpy2.powmod(random_unit(p), (p - 1) // order, p)
        if all(gmpy2.powmod(x, order // f, p) != 1 for f in order_factors):
            return x


class DGKPrivateKey:
    """Key holder's factors and subgroup orders; CRT encryption and zero test."""

    __slots__ = (
        "_gp",
        "_gq",
        "_hp",
        "_hq",
        "_p_inv_q",
        "_zero_table",
        "p",
        "public_key",
        "q",
        "vp",
        "vq",
    )

    def __init__(
        self,
        p: int,
        q: int,
        vp: int,
        vq: int,
        gp: int,
        gq: int,
        hp: int,
        hq: int,
        u: int,
        t: int,
        *,
        insecure_for_tests: bool = False,
    ) -> None:
        self.p, self.q, self.vp, self.vq = mpz(p), mpz(q), mpz(vp), mpz(vq)
        self._gp, self._gq, self._hp, self._hq = mpz(gp), mpz(gq), mpz(hp), mpz(hq)
        self._p_inv_q = gmpy2.invert(self.p, self.q)
        g = crt_pair(self._gq, self._gp, self.q, self.p, self._p_inv_q)
        h = crt_pair(self._hq, self._hp, self.q, self.p, self._p_inv_q)
        self.public_key = DGKPublicKey(
            self.p * self.q, g, h, u, t, insecure_for_tests=insecure_for_tests
        )
        self.public_key.noise_pool = NoisePool(self._crt_noise)
        base = gmpy2.powmod(self._gp, self.vp, self.p)
        self._zero_table = {int(gmpy2.powmod(base, m, self.p)): m for m in range(u)}

    @classmethod
    def generate(
        cls,
        bits: int = 2048,
        t: int = 224,
        comparison_bits: int = 64,
        *,
        insecure_for_tests: bool = False,
    ) -> DGKPrivateKey:
        """A key whose u fits comparisons of up to ``comparison_bits`` bits."""
        check_modulus_bits(bits, insecure_for_tests)
        check_dgk_t(t, insecure_for_tests)
        u = u_for_bits(comparison_bits)
        while True:
            vp, vq = random_prime(t), random_prime(t)
            if vp == vq:
                continue
            p = _dgk_prime(bits // 2, u, vp)
            q = _dgk_prime(bits - bits // 2, u, vq)
            if p == q or (p * q).bit_length() != bits:
                continue
            # DGK 2009 correction: v_p must not divide q - 1, nor v_q divide p - 1.
            if (q - 1) % vp == 0 or (p - 1) % vq == 0:
                continue
            gp, gq = _element_of_order(p, (u, int(vp))), _element_of_order(q, (u, int(vq)))
            hp, hq = _element_of_order(p, (int(vp),)), _element_of_order(q, (int(vq),))
            return cls(p, q, vp, vq, gp, gq, hp, hq, u, t, insecure_for_tests=insecure_for_tests)

    def _crt_noise(self) -> mpz:
        """h^r with r uniform modulo v_p v_q, computed with t-bit exponents modulo p and q."""
        rp = gmpy2.powmod(self._hp, mpz(secrets.randbelow(int(self.vp))), self.p)
        rq = gmpy2.powmod(self._hq, mpz(secrets.randbelow(int(self.vq))), self.q)
        return crt_pair(rq, rp, self.q, self.p, self._p_inv_q)

    def encrypt_batch(self, values: Sequence[int]) -> bytes:
        """Fresh encryptions of ``values``, as wire bytes (``width`` bytes each)."""
        pub = self.public_key
        return b"".join(pub.encrypt(m).to_bytes() for m in values)

    def is_zero(self, c: DGKCiphertext) -> bool:
        """m == 0 (mod u)  iff  c^(v_p) == 1 (mod p)."""
        return bool(gmpy2.powmod(c.value, self.vp, self.p) == 1)

    def decrypt(self, c: DGKCiphertext) -> int:
        """m in [0, u) through a table of (g^(v_p))^m mod p."""
        key = int(gmpy2.powmod(c.value, self.vp, self.p))
        try:
            return self._zero_table[key]
        except KeyError:
            raise RemoteProtocolError("not a valid DGK ciphertext") from None


class DGKCiphertext:
    """An element of Z_n^* with operators; plaintexts live in Z_u."""

    __slots__ = ("fresh", "key", "value")

    def __init__(self, key: DGKPublicKey, value: mpz, *, fresh: bool = False) -> None:
        self.key, self.value, self.fresh = key, value, fresh

    def __add__(self, other: DGKCiphertext | int) -> DGKCiphertext:
        if isinstance(other, DGKCiphertext):
            return DGKCiphertext(self.key, (self.value * other.value) % self.key.n)
        return DGKCiphertext(self.key, (self.value * self.key.g_pow(other)) % self.key.n)

    __radd__ = __add__

    def __neg__(self) -> DGKCiphertext:
        return DGKCiphertext(self.key, gmpy2.invert(self.value, self.key.n))

    def __sub__(self, other: DGKCiphertext | int) -> DGKCiphertext:
        return self + (-other)

    def __rsub__(self, other: int) -> DGKCiphertext:
        return (-self) + other

    def __mul__(self, k: int) -> DGKCiphertext:
        if isinstance(k, DGKCiphertext):
            raise LocalProtocolError("DGK cannot multiply two ciphertexts")
        return DGKCiphertext(self.key, gmpy2.powmod(self.value, k % self.key.u, self.key.n))

    __rmul__ = __mul__

    def to_bytes(self) -> bytes:
        if not self.fresh:
            raise LocalProtocolError("refusing to send a DGK ciphertext that is not fresh")
        return int_to_fixed(int(self.value), self.key.width)
