"""Secure comparison with XOR-shared output: Veugen's DGK-based protocol, batched, sans-IO.

Alice holds Paillier encryptions [x_j - y_j] under Bob's key, for signed l-bit x_j, y_j.  At the
end Alice holds bits a_j and Bob bits b_j with a_j XOR b_j = [x_j >= y_j]; neither learns the
result.  One and a half round trips for any number of comparisons:

1. Alice (:meth:`ComparisonAlice.mask`): z_j = x_j - y_j + 2^l in [1, 2^(l+1)); she adds a
   uniform r_j of l + kappa + 1 bits, so d_j = z_j + r_j hides z_j to within 2^-kappa, and
   packs as many d_j as fit into one Paillier plaintext (slots of l + kappa + 2 bits).
2. Bob (:meth:`ComparisonBob.decompose`): decrypts, keeps D_j = bit l of d_j, and sends the l
   bits of d_j mod 2^l encrypted with the zero-test scheme (DGK or EC-ElGamal).
3. Alice (:meth:`ComparisonAlice.compare_bits`): with s = 1 - 2 delta_A for a uniform bit
   delta_A and w_i = d_i XOR r_i (Veugen 2012, eq. for c_i)
       c_i    = s + d_i - r_i + 3 * sum_{k > i} w_k      (i = l-1 .. 0)
       c_(-1) = 3 (1 - delta_A) + 3 * sum_k w_k          (the equality term)
   Exactly one c is zero iff delta_A XOR [d^ < r^] = 1, where d^ = d mod 2^l, r^ = r mod 2^l.
   Each c is multiplied by a uniform rho != 0 and re-randomised, the l + 1 values shuffled.
4. Bob (:meth:`ComparisonBob.zero_test`): delta_B = [some c is zero].

Since z_j >> l = (d_j >> l) - (r_j >> l) - [d^ < r^], bit l of z_j, which is [x_j >= y_j], is
D_j XOR R_j XOR delta_A XOR delta_B: Alice's share is R_j XOR delta_A (R_j = bit l of r_j) and
Bob's is D_j XOR delta_B.  No Paillier message flows back to Alice at all.

What each side sees is argued in ``docs/security.md``.
"""

from __future__ import annotations

import enum
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Generic

from .encoding import Reader
from .errors import LocalProtocolError, RemoteProtocolError
from .paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from .params import check_kappa
from .zerotest import C, ZeroTestPrivateKey, ZeroTestPublicKey

_system_random = secrets.SystemRandom()


def slot_bits(l: int, kappa: int) -> int:
    """Width of one packed d_j: d_j < 2^(l+1) + 2^(l+kappa+1) <= 2^(l+kappa+2)."""
    return l + kappa + 2


def slots_per_ciphertext(key: PaillierPublicKey, l: int, kappa: int) -> int:
    """How many d_j fit below n."""
    return max(1, (key.n.bit_length() - 1) // slot_bits(l, kappa))


def packed_count(key: PaillierPublicKey, l: int, kappa: int, count: int) -> int:
    """Paillier ciphertexts in step 1 for ``count`` comparisons."""
    per = slots_per_ciphertext(key, l, kappa)
    return (count + per - 1) // per


def check_shape(l: int, kappa: int, count: int, plaintext_modulus: int) -> None:
    """Public parameters both sides must agree on; refuse what the schemes cannot carry."""
    if not 1 <= l <= 256:
        raise LocalProtocolError(f"comparison bit length {l} out of range 1..256")
    if count < 1:
        raise LocalProtocolError("at least one comparison is needed")
    if 3 * l + 3 >= plaintext_modulus:
        raise LocalProtocolError(f"bit scheme plaintext space too small for l = {l}")


class State(enum.Enum):
    """States of either party; any error moves to FAILED, which is final."""

    START = "start"
    WAIT_BITS = "wait-bits"  # Alice, after step 1
    WAIT_MASKED = "wait-masked"  # Bob, before step 2
    WAIT_TESTS = "wait-tests"  # Bob, after step 2
    DONE = "done"
    FAILED = "failed"


# --------------------------------------------------------------------------- messages


@dataclass(frozen=True, slots=True)
class MaskedDifferences:
    """Step 1, Alice -> Bob: packed Paillier encryptions of d_j = z_j + r_j."""

    ciphertexts: tuple[PaillierCiphertext, ...]

    def to_bytes(self) -> bytes:
        return b"".join(c.to_bytes() for c in self.ciphertexts)

    @classmethod
    def read(cls, reader: Reader, key: PaillierPublicKey, packed: int) -> MaskedDifferences:
        return cls(tuple(key.read_ciphertext(reader) for _ in range(packed)))


@dataclass(frozen=True, slots=True)
class BitDecompositions:
    """Step 2, Bob -> Alice: the l low bits of every d_j, encrypted (a key holder's batch)."""

    payload: bytes

    def to_bytes(self) -> bytes:
        return self.payload

    @classmethod
    def read(cls, reader: Reader, size: int) -> BitDecompositions:
        return cls(reader.take(size))


@dataclass(frozen=True, slots=True)
class BlindedTests(Generic[C]):
    """Step 3, Alice -> Bob: l + 1 blinded, shuffled c values per comparison."""

    ciphertexts: tuple[C, ...]

    def to_bytes(self) -> bytes:
        return b"".join(c.to_bytes() for c in self.ciphertexts)

    @classmethod
    def read(cls, reader: Reader, key: ZeroTestPublicKey[C], count: int) -> BlindedTests[C]:
        return cls(tuple(key.read_ciphertext(reader) for _ in range(count)))


# --------------------------------------------------------------------------- Alice


class ComparisonAlice(Generic[C]):
    """The party without keys.  ``differences[j]`` encrypts x_j - y_j under Bob's key."""

    def __init__(
        self,
        paillier: PaillierPublicKey,
        bits: ZeroTestPublicKey[C],
        l: int,
        kappa: int,
        differences: Sequence[PaillierCiphertext],
        *,
        insecure_for_tests: bool = False,
    ) -> None:
        check_kappa(kappa, insecure_for_tests)
        check_shape(l, kappa, len(differences), bits.plaintext_modulus)
        self.paillier, self.bits, self.l, self.kappa = paillier, bits, l, kappa
        self._differences = list(differences)
        self.count = len(differences)
        self.state = State.START
        self._r: list[int] = []
        self._delta: list[int] = []
        self._shares: list[int] = []

    @property
    def shares(self) -> list[int]:
        """Alice's XOR shares of [x_j >= y_j], available after step 3."""
        if self.state is not State.DONE:
            raise LocalProtocolError(f"shares are not ready in state {self.state.value}")
        return list(self._shares)

    def _expect(self, state: State) -> None:
        if self.state is not state:
            raise LocalProtocolError(f"Alice is in state {self.state.value}, not {state.value}")

    def mask(self) -> MaskedDifferences:
        """Step 1: [d_j] = [x_j - y_j] + 2^l + r_j, packed by Horner's rule, re-randomised."""
        self._expect(State.START)
        l, w = self.l, slot_bits(self.l, self.kappa)
        per = slots_per_ciphertext(self.paillier, l, self.kappa)
        self._r = [secrets.randbits(l + self.kappa + 1) for _ in range(self.count)]
        packed: list[PaillierCiphertext] = []
        for start in range(0, self.count, per):
            group = range(start, min(start + per, self.count))
            acc: PaillierCiphertext | None = None
            offset = 0
            for j in reversed(group):
                acc = self._differences[j] if acc is None else acc * (1 << w) + self._differences[j]
                offset = (offset << w) + (1 << l) + self._r[j]
            assert acc is not None
            packed.append((acc + offset).rerandomize())
        self.state = State.WAIT_BITS
        return MaskedDifferences(tuple(packed))

    def bits_size(self) -> int:
        """Exact byte size of Bob's step-2 message."""
        return self.bits.batch_size(self.count * self.l)

    def compare_bits(self, msg: BitDecompositions) -> BlindedTests[C]:
        """Step 3: the c_i of every comparison, blinded, re-randomised and shuffled."""
        self._expect(State.WAIT_BITS)
        try:
            reader = Reader(msg.payload)
            d_bits = self.bits.read_batch(reader, self.count * self.l)
            reader.finish()
        except RemoteProtocolError:
            self.state = State.FAILED
            raise
        out: list[C] = []
        for j in range(self.count):
            delta = secrets.randbits(1)
            self._delta.append(delta)
            out.extend(self._blinded_cs(d_bits[j * self.l : (j + 1) * self.l], self._r[j], delta))
            self._shares.append(((self._r[j] >> self.l) & 1) ^ delta)
        self.state = State.DONE
        return BlindedTests(tuple(out))

    def _blinded_cs(self, d: Sequence[C], r: int, delta: int) -> list[C]:
        return veugen_tests(self.bits, d, r, delta, self.l)


def veugen_tests(bits: ZeroTestPublicKey[C], d: Sequence[C], r: int, delta: int, l: int) -> list[C]:
    """Veugen's c_i and the equality term for one comparison, blinded and shuffled.

    ``d`` are Bob's encrypted bits of d mod 2^l, ``r`` Alice's mask (only its l low bits
    matter).  Exactly one result encrypts zero iff delta XOR [d mod 2^l < r mod 2^l] = 1.
    The same operations run for any r and delta.
    """
    s = 1 - 2 * delta
    three_w = bits.constant(0)  # 3 * sum_{k > i} w_k
    cs: list[C] = []
    for i in reversed(range(l)):
        r_i = (r >> i) & 1
        cs.append(d[i] + (s - r_i) + three_w)
        w_i = (d[i], 1 - d[i])[r_i]  # d_i XOR r_i, both branches computed
        three_w = three_w + w_i + w_i + w_i
    cs.append(three_w + 3 * (1 - delta))
    blinded = [bits.blind(c) for c in cs]
    _system_random.shuffle(blinded)
    return blinded


# --------------------------------------------------------------------------- Bob


class ComparisonBob(Generic[C]):
    """The key holder."""

    def __init__(
        self,
        paillier: PaillierPrivateKey,
        bits: ZeroTestPrivateKey[C],
        l: int,
        kappa: int,
        count: int,
        *,
        insecure_for_tests: bool = False,
    ) -> None:
        check_kappa(kappa, insecure_for_tests)
        check_shape(l, kappa, count, bits.public_key.plaintext_modulus)
        self.paillier, self.bits, self.l, self.kappa, self.count = paillier, bits, l, kappa, count
        self.state = State.WAIT_MASKED
        self._high: list[int] = []
        self._shares: list[int] = []

    @property
    def shares(self) -> list[int]:
        """Bob's XOR shares of [x_j >= y_j], available after step 4."""
        if self.state is not State.DONE:
            raise LocalProtocolError(f"shares are not ready in state {self.state.value}")
        return list(self._shares)

    def _expect(self, state: State) -> None:
        if self.state is not state:
            raise LocalProtocolError(f"Bob is in state {self.state.value}, not {state.value}")

    def masked_count(self) -> int:
        return packed_count(self.paillier.public_key, self.l, self.kappa, self.count)

    def decompose(self, msg: MaskedDifferences) -> BitDecompositions:
        """Step 2: decrypt, unpack, keep bit l, encrypt the l low bits of each d_j."""
        self._expect(State.WAIT_MASKED)
        w = slot_bits(self.l, self.kappa)
        per = slots_per_ciphertext(self.paillier.public_key, self.l, self.kappa)
        if len(msg.ciphertexts) != self.masked_count():
            self.state = State.FAILED
            raise RemoteProtocolError("wrong number of masked differences")
        values: list[int] = []
        for index, ct in enumerate(msg.ciphertexts):
            packed = self.paillier.decrypt(ct)
            slots = min(per, self.count - index * per)
            if packed >> (w * slots):
                self.state = State.FAILED
                raise RemoteProtocolError("masked difference out of range")
            values.extend((packed >> (w * k)) & ((1 << w) - 1) for k in range(slots))
        self._high = [(d >> self.l) & 1 for d in values]
        low_bits = [(d >> i) & 1 for d in values for i in range(self.l)]
        self.state = State.WAIT_TESTS
        return BitDecompositions(self.bits.encrypt_batch(low_bits))

    def tests_count(self) -> int:
        return self.count * (self.l + 1)

    def zero_test(self, msg: BlindedTests[C]) -> None:
        """Step 4: delta_B = [some c is zero]; every c is tested, no early exit."""
        self._expect(State.WAIT_TESTS)
        if len(msg.ciphertexts) != self.tests_count():
            self.state = State.FAILED
            raise RemoteProtocolError("wrong number of blinded tests")
        zeros = [self.bits.is_zero(c) for c in msg.ciphertexts]
        group = self.l + 1
        for j in range(self.count):
            found = sum(zeros[j * group : (j + 1) * group])
            if found > 1:
                self.state = State.FAILED
                raise RemoteProtocolError("more than one zero in a comparison")
            self._shares.append(self._high[j] ^ found)
        self.state = State.DONE
