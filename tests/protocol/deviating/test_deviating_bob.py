"""A deviating Bob's keys (paper suite): a modulus with a factor he knows the order of lets
what he decrypts depend on Alice's secrets (her masks multiplied into his ciphertexts).  The
decoders refuse a modulus with a factor below 2^16 -- the cheap case, n = 3 * P; two large
factors of a bad form are caught by the modulus proof in his KEYS message (D2).  His DGK key
and the range of his ciphertexts carry no proof (D3): the paper suite starts only when the
caller vouches for the peer (``trusted_keys``; the companion's ``paper_keys``,
tests/companion/attacks/test_deviating_peer.py, docs/security.md)."""

from __future__ import annotations

from typing import Any

import gmpy2
import pytest

from protocol.errors import RemoteProtocolError, UntrustedKeysError
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.paper import keyproof
from protocol.primitives.dgk import DGKPublicKey
from protocol.primitives.paillier import PaillierPublicKey
from protocol.primitives.primes import has_small_factor, random_prime
from protocol.run import State
from protocol.wire.encoding import int_to_fixed
from tests.protocol.paths import GRID

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


# --------------------------------------------------------------------------- the modulus proof


def _bad_modulus() -> tuple[int, int, int]:
    """N = p q with p | q - 1: gcd(N, phi(N)) = p, and no factor below 2^16 (p has 64 bits)."""
    p = int(random_prime(64))
    k = (1 << 2047) // (p * p) + 1  # N = p (k p + 1) then has 2048 bits
    k += k % 2  # even, so that q is odd
    while True:
        q = k * p + 1
        if (p * q).bit_length() == 2048 and gmpy2.is_prime(q):
            return p * q, p, q
        k += 2  # k even: q odd


def test_an_honest_paillier_key_proves_itself(keys: Any) -> None:
    proof = keyproof.prove(keys.paillier)
    assert len(proof) == keyproof.proof_size(keys.paillier_pub) == 7 * 256
    keyproof.verify(keys.paillier_pub, proof)
    with pytest.raises(RemoteProtocolError, match="proof"):
        keyproof.verify(keys.paillier_pub, proof[:-1] + bytes([proof[-1] ^ 1]))
    with pytest.raises(RemoteProtocolError, match="proof"):
        keyproof.verify(keys.paillier_pub, proof[:-1])


def test_a_modulus_with_gcd_n_phi_not_one_cannot_prove_itself() -> None:
    """D2: N = p q with p | q - 1 passes every check of the decoder (odd, composite, no small
    factor, not a square), but s -> s^N is p-to-one on Z_N^*: Alice's fresh noise would not
    hide how she combined Bob's ciphertexts.  Its holder knows p and q and still cannot make
    the proof: a challenge has an N-th root with probability 1/p, and the best he can send --
    the roots of the challenges' N-th-residue parts -- fails."""
    n, p, q = _bad_modulus()
    key = PaillierPublicKey.from_bytes(int_to_fixed(n, 256))  # the decoder accepts it
    order = (p - 1) * (q - 1) // p  # the N-th powers form a subgroup of this order
    e = int(gmpy2.invert(n, order))
    forged = b"".join(
        int_to_fixed(int(gmpy2.powmod(rho, e, n)), 256) for rho in keyproof.challenges(n)
    )
    with pytest.raises(RemoteProtocolError, match="proof"):
        keyproof.verify(key, forged)


def test_alice_checks_the_proof_before_touching_bobs_ciphertexts(keys: Any) -> None:
    """A KEYS message whose proof does not check ends the run at Alice, before she computes
    anything on Bob's ciphertexts (nothing of hers goes back)."""
    alice = Alice(((0, 0), (5, 5)), GRID, suite=Suite.PAPER, trusted_keys=True)
    bob = Bob(((0, 5), (5, 0)), keys=keys.bob)
    reply = bob.receive(alice.start())
    assert reply is not None
    proof = keys.bob.paillier_proof
    at = reply.index(proof)
    broken = reply[:at] + bytes([proof[0] ^ 1]) + reply[at + 1 :]
    with pytest.raises(RemoteProtocolError, match="proof"):
        alice.receive(broken)
    assert alice.state is State.FAILED


# --------------------------------------------------------------------------- D3: untrusted keys


def test_the_paper_suite_does_not_start_without_trusted_keys(keys: Any) -> None:
    """D3: Alice cannot check the range of Bob's Paillier plaintexts (2^1300 as a coordinate
    puts her coefficients above the masked slots) nor his DGK key, so the sans-IO core itself
    refuses the paper suite unless the caller vouches for the peer: no HELLO, no machine.  The
    compact suite needs no such trust."""
    with pytest.raises(UntrustedKeysError, match="trusted_keys"):
        Alice(((0, 0), (5, 5)), GRID, suite=Suite.PAPER)
    assert Alice(((0, 0), (5, 5)), GRID).state is State.START  # compact: no trust asked
    trusted = Alice(((0, 0), (5, 5)), GRID, suite=Suite.PAPER, trusted_keys=True)
    assert Bob(((0, 5), (5, 0)), keys=keys.bob).receive(trusted.start()) is not None
