"""The consistency check of the OT extension: a chooser who deviates is caught (sans-IO).

Without it a deviating chooser (Bob) could send an extension message that is not the honest
one for his leaves -- flip bits of some block's d_b, or corrupt the setup's GGM corrections --
so that Alice's rows satisfy q_i = t_i xor c_i Delta only if some bits of her Delta are what
he guessed.  Whether the run then works out (her answer, her climb) tells him those bits: a
selective-failure attack, one run at a time, on the Delta that protects every run with him.

The check is the one of Keller, Orsini and Scholl (CRYPTO 2015, figure 7, "KOS"), which
SoftSpokenOT (Roy, CRYPTO 2022, section 5) applies to its subspace VOLE; with Fiat-Shamir, as
libOTe and others do, so that it costs no round trip:

* both derive challenges chi_i in GF(2^kappa), one per OT, from the run nonce and Bob's
  extension message (:func:`challenges`);
* Bob sends x = sum chi_i c_i and t = sum chi_i t_i, reading each row t_i (kappa bits) as a
  field element;
* Alice checks sum chi_i q_i = t + x Delta, which holds for the honest rows by linearity.

Rows with an error that depends on Delta -- whatever Bob did to his message or to the setup --
pass only if he guessed the bits of Delta the error depends on (KOS, lemma 1): he then learns c
bits with probability 2^-c, and a failed check ends the run *and* the setup (the companion
drops it; a new setup has a new Delta), so guessing again does not add up.  ``kappa + 40``
extra OTs, whose choice bits are never used, make x uniform (statistical distance 2^-40):
the check tells Alice nothing about Bob's other choice bits, which carry his values.

Costs: (blocks - 1) (kappa + 40) bits of extension and 2 kappa bits of reply, 199 bytes at
kappa = 112 (ten blocks); Alice's check is one pass over her columns.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from protocol.errors import ConsistencyError, RemoteProtocolError

Bytes = npt.NDArray[np.uint8]
STATISTICAL = 40  # the extra OTs beyond kappa: x is within 2^-40 of uniform


@dataclass(frozen=True, slots=True)
class Field:
    """GF(2^bits) as polynomials over GF(2) modulo an irreducible ``modulus`` (bit i = x^i)."""

    bits: int
    modulus: int

    def times_x(self, a: int) -> int:
        a <<= 1
        return a ^ self.modulus if a >> self.bits else a

    def mul(self, a: int, b: int) -> int:
        out = 0
        for i in reversed(range(b.bit_length())):
            out = self.times_x(out)
            if (b >> i) & 1:
                out ^= a
        return out

    @property
    def size(self) -> int:
        return self.bits // 8


# x^112 + x^15 + x^10 + x + 1 (the lowest irreducible pentanomial of degree 112; there is no
# irreducible trinomial) and GCM's x^128 + x^7 + x^2 + x + 1; the tests check both.
FIELDS = {
    112: Field(112, (1 << 112) | (1 << 15) | (1 << 10) | (1 << 1) | 1),
    128: Field(128, (1 << 128) | (1 << 7) | (1 << 2) | (1 << 1) | 1),
}


def field(kappa: int) -> Field:
    try:
        return FIELDS[kappa]
    except KeyError:
        raise RemoteProtocolError(f"no consistency check for kappa = {kappa}") from None


def extra_ots(kappa: int) -> int:
    """OTs that exist only to mask Bob's reply."""
    return kappa + STATISTICAL


def reply_size(kappa: int) -> int:
    """Bytes of Bob's reply: x and t."""
    return 2 * field(kappa).size


def challenges(nonce: bytes, message: bytes, count: int, kappa: int) -> npt.NDArray[np.uint64]:
    """chi_0 .. chi_(count-1), each as (low 64 bits, high 64 bits): a random oracle on the run
    nonce and Bob's whole extension message, so he fixes the rows before he sees them."""
    bits = field(kappa).bits
    digest = hashlib.blake2b(message, digest_size=32, person=b"pdc/ot/check/v1").digest()
    raw = hashlib.shake_128(b"pdc/ot/chi/v1" + nonce + digest).digest(16 * count)
    chi = np.frombuffer(raw, dtype="<u8").reshape(count, 2).copy()
    chi[:, 1] &= np.uint64((1 << (bits - 64)) - 1)
    return chi


def _element(pair: npt.NDArray[np.uint64]) -> int:
    return int(pair[0]) | int(pair[1]) << 64


def _select(bits: npt.NDArray[np.bool_], chi: npt.NDArray[np.uint64]) -> int:
    """XOR of the chi_i whose bit is set."""
    return _element(np.bitwise_xor.reduce(chi[bits], axis=0))


def fold_rows(columns: Sequence[Bytes], chi: npt.NDArray[np.uint64], kappa: int) -> int:
    """sum_i chi_i r_i for the rows r_i = sum_j column_j[i] x^j, computed by columns:
    sum_j x^j (XOR of chi_i over the set bits of column j), by Horner's rule."""
    gf = field(kappa)
    if len(columns) != gf.bits:
        raise RemoteProtocolError("one column per bit of Delta")
    count = len(chi)
    bits = np.unpackbits(np.stack(columns), axis=1, bitorder="little")[:, :count].astype(bool)
    acc = 0
    for j in reversed(range(gf.bits)):
        acc = gf.times_x(acc) ^ _select(bits[j], chi)
    return acc


def fold_choices(choices: Bytes, chi: npt.NDArray[np.uint64]) -> int:
    """x = sum_i chi_i c_i."""
    bits = np.unpackbits(choices, bitorder="little")[: len(chi)].astype(bool)
    return _select(bits, chi)


def respond(
    columns: Sequence[Bytes], choices: Bytes, nonce: bytes, message: bytes, count: int
) -> bytes:
    """Bob: x and t for the first ``count`` rows of ``columns`` (his t_i) and choice bits
    (the bits beyond, padding to whole bytes, are no OTs and satisfy no relation)."""
    kappa = len(columns)
    chi = challenges(nonce, message, count, kappa)
    size = field(kappa).size
    x, t = fold_choices(choices, chi), fold_rows(columns, chi, kappa)
    return x.to_bytes(size, "big") + t.to_bytes(size, "big")


def verify(
    columns: Sequence[Bytes],
    delta: int,
    nonce: bytes,
    message: bytes,
    count: int,
    reply: bytes,
) -> None:
    """Alice: raise :class:`ConsistencyError` unless sum chi_i q_i = t + x Delta.  ``delta``
    holds Delta's bits in column order (bit j = column j); the first ``count`` rows count."""
    kappa = len(columns)
    gf = field(kappa)
    if len(reply) != 2 * gf.size:
        raise RemoteProtocolError("OT consistency reply has the wrong size")
    x = int.from_bytes(reply[: gf.size], "big")
    t = int.from_bytes(reply[gf.size :], "big")
    if x >> gf.bits or t >> gf.bits:
        raise RemoteProtocolError("OT consistency reply is not a field element")
    chi = challenges(nonce, message, count, kappa)
    q = fold_rows(columns, chi, kappa)
    expected = t ^ gf.mul(x, delta)
    if not hmac.compare_digest(q.to_bytes(gf.size, "big"), expected.to_bytes(gf.size, "big")):
        raise ConsistencyError("the peer's OT extension fails the consistency check")
