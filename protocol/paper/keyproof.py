"""Bob proves his Paillier modulus fit for Alice's computations: gcd(N, phi(N)) = 1.

Alice multiplies Bob's ciphertexts by her coefficients and hides *how* with fresh noise s^N
(paper suite, MASKED).  That hides it only if s -> s^N is a bijection of Z_N^*, i.e.
gcd(N, phi(N)) = 1: then every ciphertext is (1 + N)^m r^N for exactly one (m, r) and her
result's noise is uniform whatever Bob's ciphertexts were.  With a modulus of another form
(a square factor, or p | q - 1) her noise lives in a subgroup, and the noise of Bob's own
ciphertexts, raised to her coefficients, shows through.

The proof is Goldberg, Reyzin, Sagga and Baldimtsi's ("Efficient noninteractive certification
of RSA moduli and beyond", ASIACRYPT 2019, section 3.2): N-th roots of challenges rho_i that
both derive from N by hashing (Fiat-Shamir).  If a prime p divides N and phi(N), at most a
1/p share of Z_N^* are N-th residues; the decoder already refuses a modulus with a factor
below 2^16 (:func:`protocol.primitives.primes.has_small_factor`), so p > 2^16 and ``ROOTS`` = 7
roots leave a bad modulus a chance below 2^-112 (the project's level).  1792 bytes for a 2048-bit N,
made once per key by Bob; Alice checks a key once (7 exponentiations, 17 ms here) and
remembers it (:func:`verify` caches by the key and the proof).
"""

from __future__ import annotations

import functools
import hashlib

import gmpy2
from gmpy2 import mpz

from protocol.errors import RemoteProtocolError
from protocol.primitives.paillier import PaillierPrivateKey, PaillierPublicKey
from protocol.primitives.primes import SMALL_FACTOR_BOUND
from protocol.wire.encoding import int_to_fixed

SECURITY = 112
ROOTS = -(-SECURITY // (SMALL_FACTOR_BOUND.bit_length() - 1))  # 112 / 16 = 7


def proof_size(key: PaillierPublicKey) -> int:
    return ROOTS * key.width


def challenges(n: mpz) -> list[mpz]:
    """rho_1 .. rho_ROOTS in [1, N): SHAKE256 of N and the index, 128 bits longer than N
    before the reduction (statistically uniform)."""
    width = (n.bit_length() + 7) // 8
    out = []
    for i in range(ROOTS):
        raw = hashlib.shake_256(
            b"pdc/paillier-key-proof/v1" + int_to_fixed(int(n), width) + bytes([i])
        ).digest(width + 16)
        out.append(mpz(int.from_bytes(raw, "big")) % n)
    return out


def prove(key: PaillierPrivateKey) -> bytes:
    """The key holder's proof: rho_i^(N^-1 mod phi(N)) mod N for each challenge (CRT)."""
    p, q = key.p, key.q
    n = p * q
    dp, dq = gmpy2.invert(n, p - 1), gmpy2.invert(n, q - 1)
    q_inv = gmpy2.invert(q, p)
    width = key.public_key.width
    roots = []
    for rho in challenges(n):
        sp, sq = gmpy2.powmod(rho, dp, p), gmpy2.powmod(rho, dq, q)
        root = sq + q * ((sp - sq) * q_inv % p)
        roots.append(int_to_fixed(int(root), width))
    return b"".join(roots)


def verify(key: PaillierPublicKey, proof: bytes) -> None:
    """Alice: raise :class:`RemoteProtocolError` unless every root checks (sigma^N = rho mod
    N, sigma a unit).  Relies on the decoder's small-factor check (see the module text)."""
    if not _verified(int_to_fixed(int(key.n), key.width), proof):
        raise RemoteProtocolError("peer's Paillier modulus fails its proof (gcd(N, phi(N)) != 1)")


@functools.lru_cache(maxsize=64)
def _verified(modulus: bytes, proof: bytes) -> bool:
    """Whether ``proof`` holds for the modulus (cached: a key is checked once, however many
    runs carry it)."""
    n = mpz(int.from_bytes(modulus, "big"))
    width = len(modulus)
    if len(proof) != ROOTS * width:
        return False
    for i, rho in enumerate(challenges(n)):
        sigma = mpz(int.from_bytes(proof[i * width : (i + 1) * width], "big"))
        if not 0 < sigma < n or gmpy2.gcd(sigma, n) != 1 or gmpy2.gcd(rho, n) != 1:
            return False
        if gmpy2.powmod(sigma, n, n) != rho:
            return False
    return True
