"""Prime generation and modular helpers on gmpy2, with randomness from :mod:`secrets` only."""

from __future__ import annotations

import functools
import secrets

import gmpy2
from gmpy2 import mpz

MILLER_RABIN_ROUNDS = 40


def random_unit(modulus: int) -> mpz:
    """Uniform element of Z_modulus^* (rejection sampling; for RSA moduli one try suffices)."""
    while True:
        r = mpz(secrets.randbelow(int(modulus)))
        if r > 0 and gmpy2.gcd(r, modulus) == 1:
            return r


def is_probable_prime(n: int) -> bool:
    return bool(gmpy2.is_prime(mpz(n), MILLER_RABIN_ROUNDS))


def random_prime(bits: int) -> mpz:
    """Uniform-start random prime of exactly ``bits`` bits, top two bits set.

    Setting the two top bits makes the product of two such primes exactly ``2 * bits`` long.
    """
    if bits < 16:
        raise ValueError("prime too small")
    while True:
        candidate = mpz(secrets.randbits(bits)) | (mpz(3) << (bits - 2)) | 1
        p = gmpy2.next_prime(candidate)
        if p.bit_length() == bits and is_probable_prime(p):
            return p


def crt_pair(rp: int, rq: int, p: int, q: int, q_inv_p: int) -> mpz:
    """The x mod p*q with x = rp (mod p), x = rq (mod q), given q^-1 mod p (Garner)."""
    h = ((mpz(rp) - rq) * q_inv_p) % p
    return mpz(rq) + h * q


SMALL_FACTOR_BOUND = 1 << 16


@functools.cache
def _small_primorial() -> mpz:
    """The product of the primes below SMALL_FACTOR_BOUND (about 94,000 bits)."""
    product, p = mpz(1), mpz(2)
    while p < SMALL_FACTOR_BOUND:
        product *= p
        p = gmpy2.next_prime(p)
    return product


def has_small_factor(n: int) -> bool:
    """Whether a prime below 2^16 divides ``n``: a peer's modulus built as 3 * P (a factor
    it knows the order of) is refused at once.  What this cannot see -- two large factors
    of a bad form -- needs a proof of the modulus (docs/security.md)."""
    return gmpy2.gcd(mpz(n), _small_primorial()) != 1
