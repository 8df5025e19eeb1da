"""Secure comparison with XOR-shared output: Veugen's DGK-based protocol, batched (paper suite).

Alice holds Paillier encryptions of values v_j under Bob's key, several packed per ciphertext,
and for each value one or more private thresholds theta.  At the end Alice holds bits a and Bob
bits b with a XOR b = [v_j >= theta] for every (j, theta); neither learns the result.  One and
a half round trips for any number of comparisons:

1. Alice (:meth:`ComparisonAlice.mask`): z_j = v_j + 2^l in (0, 2^(l+1)); she adds a uniform
   r_j of l + kappa + 1 bits, so d_j = z_j + r_j hides z_j to within 2^-kappa, slot by slot
   (slots of l + kappa + 2 bits), and re-randomises.
2. Bob (:meth:`ComparisonBob.decompose`): decrypts, keeps D_j = bit l of d_j, and sends the l
   bits of d_j mod 2^l DGK-encrypted.
3. Alice (:meth:`ComparisonAlice.compare_bits`): for each threshold she shifts her mask,
   r' = r_j + theta (then d_j - r' = v_j - theta + 2^l: one decomposition serves every
   threshold), and with s = 1 - 2 delta_A for a uniform bit delta_A and w_i = d_i XOR r'_i
   (Veugen 2012)
       c_i    = s + d_i - r'_i + 3 * sum_{k > i} w_k      (i = l-1 .. 0)
       c_(-1) = 3 (1 - delta_A) + 3 * sum_k w_k          (the equality term)
   Exactly one c is zero iff delta_A XOR [d^ < r'^] = 1 (d^ = d mod 2^l, r'^ = r' mod 2^l).
   Each c is multiplied by a uniform rho != 0, re-randomised, the l + 1 values shuffled.
4. Bob (:meth:`ComparisonBob.zero_test`): delta_B = [some c is zero].

Since (d - r') >> l = D - R' - [d^ < r'^] (R' = bit l of r'), bit l of v - theta + 2^l, i.e.
[v >= theta], is D xor R' xor delta_A xor delta_B: Alice's share is R' xor delta_A and Bob's
D xor delta_B.  What each side sees is argued in ``docs/security.md``.
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.primitives.dgk import DGKCiphertext, DGKPrivateKey, DGKPublicKey
from protocol.primitives.paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from protocol.primitives.params import check_kappa
from protocol.wire.encoding import Reader

_system_random = secrets.SystemRandom()


def slot_bits(l: int, kappa: int) -> int:
    """Width of one packed d_j: d_j < 2^(l+1) + 2^(l+kappa+1) <= 2^(l+kappa+2)."""
    return l + kappa + 2


def slots_per_ciphertext(key: PaillierPublicKey, l: int, kappa: int) -> int:
    """How many d_j fit below n."""
    return max(1, (key.n.bit_length() - 1) // slot_bits(l, kappa))


def check_shape(l: int, plaintext_modulus: int) -> None:
    """Refuse what the schemes cannot carry."""
    if not 1 <= l <= 256:
        raise LocalProtocolError(f"comparison bit length {l} out of range 1..256")
    if 3 * l + 3 >= plaintext_modulus:
        raise LocalProtocolError(f"DGK plaintext space too small for l = {l}")


@dataclass(frozen=True, slots=True)
class PackedValues:
    """One Paillier ciphertext whose slot s holds value_s - constants[s] (slot s at bit
    s * (l + kappa + 2)); Alice adds the constants while masking."""

    ciphertext: PaillierCiphertext
    constants: tuple[int, ...]


def pack_differences(
    key: PaillierPublicKey, differences: Sequence[PaillierCiphertext], l: int, kappa: int
) -> list[PackedValues]:
    """Pack single encrypted values by Horner's rule (one scalar multiplication each)."""
    w, per = slot_bits(l, kappa), slots_per_ciphertext(key, l, kappa)
    out = []
    for start in range(0, len(differences), per):
        group = differences[start : start + per]
        acc = group[-1]
        for c in reversed(group[:-1]):
            acc = acc * (1 << w) + c
        out.append(PackedValues(acc, (0,) * len(group)))
    return out


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
    """Step 2, Bob -> Alice: the l low bits of every d_j, DGK-encrypted."""

    payload: bytes

    def to_bytes(self) -> bytes:
        return self.payload


@dataclass(frozen=True, slots=True)
class BlindedTests:
    """Step 3, Alice -> Bob: l + 1 blinded, shuffled c values per (value, threshold)."""

    ciphertexts: tuple[DGKCiphertext, ...]

    def to_bytes(self) -> bytes:
        return b"".join(c.to_bytes() for c in self.ciphertexts)

    @classmethod
    def read(cls, reader: Reader, key: DGKPublicKey, count: int) -> BlindedTests:
        return cls(tuple(key.read_ciphertext(reader) for _ in range(count)))


# --------------------------------------------------------------------------- Alice


class ComparisonAlice:
    """The party without keys.  ``thresholds[j]`` are Alice's thresholds for value j (in
    packing order: slot by slot, ciphertext by ciphertext)."""

    def __init__(
        self,
        paillier: PaillierPublicKey,
        bits: DGKPublicKey,
        l: int,
        kappa: int,
        values: Sequence[PackedValues],
        thresholds: Sequence[Sequence[int]],
        *,
        insecure_for_tests: bool = False,
    ) -> None:
        check_kappa(kappa, insecure_for_tests)
        check_shape(l, bits.plaintext_modulus)
        count = sum(len(p.constants) for p in values)
        if count != len(thresholds) or not count or any(not t for t in thresholds):
            raise LocalProtocolError("one non-empty threshold list per packed value")
        if any(len(p.constants) > slots_per_ciphertext(paillier, l, kappa) for p in values):
            raise LocalProtocolError("more slots than fit a Paillier plaintext")
        self.paillier, self.bits, self.l, self.kappa = paillier, bits, l, kappa
        self._values = list(values)
        self.thresholds = [list(t) for t in thresholds]
        self.count = count
        self._r: list[int] = []
        self._shares: list[list[int]] = []

    @property
    def shares(self) -> list[list[int]]:
        """Alice's XOR shares of [v_j >= theta], per value and threshold (after step 3)."""
        if not self._shares:
            raise LocalProtocolError("shares are ready after step 3")
        return [list(s) for s in self._shares]

    def mask(self) -> MaskedDifferences:
        """Step 1: every slot gets its constant + 2^l + r_j; re-randomised."""
        if self._r:
            raise LocalProtocolError("already masked")
        l, w = self.l, slot_bits(self.l, self.kappa)
        self._r = [secrets.randbits(l + self.kappa + 1) for _ in range(self.count)]
        out = []
        position = 0
        for packed in self._values:
            offset = sum(
                (c + (1 << l) + self._r[position + s]) << (w * s)
                for s, c in enumerate(packed.constants)
            )
            position += len(packed.constants)
            out.append((packed.ciphertext + offset).rerandomize())
        return MaskedDifferences(tuple(out))

    def bits_size(self) -> int:
        return self.bits.batch_size(self.count * self.l)

    def compare_bits(self, msg: BitDecompositions) -> BlindedTests:
        """Step 3: the c_i of every (value, threshold), blinded, re-randomised, shuffled."""
        if not self._r or self._shares:
            raise LocalProtocolError("compare_bits follows mask, once")
        reader = Reader(msg.payload)
        d_bits = self.bits.read_batch(reader, self.count * self.l)
        reader.finish()
        out: list[DGKCiphertext] = []
        for j, thetas in enumerate(self.thresholds):
            d = d_bits[j * self.l : (j + 1) * self.l]
            shares = []
            for theta in thetas:
                r = self._r[j] + theta
                delta = secrets.randbits(1)
                out += veugen_tests(self.bits, d, r, delta, self.l)
                shares.append(((r >> self.l) & 1) ^ delta)
            self._shares.append(shares)
        return BlindedTests(tuple(out))


def veugen_tests(
    bits: DGKPublicKey, d: Sequence[DGKCiphertext], r: int, delta: int, l: int
) -> list[DGKCiphertext]:
    """Veugen's c_i and the equality term for one comparison, blinded and shuffled.

    ``d`` are Bob's encrypted bits of d mod 2^l, ``r`` Alice's mask (only its l low bits
    matter).  Exactly one result encrypts zero iff delta XOR [d mod 2^l < r mod 2^l] = 1.
    The same operations run for any r and delta.
    """
    s = 1 - 2 * delta
    three_w = bits.constant(0)  # 3 * sum_{k > i} w_k
    cs: list[DGKCiphertext] = []
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


class ComparisonBob:
    """The key holder.  ``slots[k]`` values in packed ciphertext k; ``thresholds[j]`` is how
    many thresholds value j has (a public count)."""

    def __init__(
        self,
        paillier: PaillierPrivateKey,
        bits: DGKPrivateKey,
        l: int,
        kappa: int,
        slots: Sequence[int],
        thresholds: Sequence[int],
        *,
        insecure_for_tests: bool = False,
    ) -> None:
        check_kappa(kappa, insecure_for_tests)
        check_shape(l, bits.public_key.plaintext_modulus)
        if sum(slots) != len(thresholds) or any(t < 1 for t in thresholds):
            raise LocalProtocolError("one threshold count per packed value")
        self.paillier, self.bits, self.l, self.kappa = paillier, bits, l, kappa
        self.slots, self.thresholds = list(slots), list(thresholds)
        self._high: list[int] = []
        self._shares: list[list[int]] = []

    @property
    def shares(self) -> list[list[int]]:
        """Bob's XOR shares, per value and threshold (after step 4)."""
        if not self._shares:
            raise LocalProtocolError("shares are ready after step 4")
        return [list(s) for s in self._shares]

    def masked_count(self) -> int:
        return len(self.slots)

    def decompose(self, msg: MaskedDifferences) -> BitDecompositions:
        """Step 2: decrypt, unpack, keep bit l, encrypt the l low bits of each d_j."""
        if self._high:
            raise LocalProtocolError("already decomposed")
        w = slot_bits(self.l, self.kappa)
        if len(msg.ciphertexts) != len(self.slots):
            raise RemoteProtocolError("wrong number of masked values")
        values: list[int] = []
        for ct, slots in zip(msg.ciphertexts, self.slots, strict=True):
            # Only the slots are read: bits above them (no honest Alice sets any) are ignored,
            # not refused -- a refusal here would tell a deviating Alice one bit of her choice
            # about Bob's values (whether a linear form of them overflowed).
            packed = self.paillier.decrypt(ct)
            values += [(packed >> (w * s)) & ((1 << w) - 1) for s in range(slots)]
        self._high = [(d >> self.l) & 1 for d in values]
        low_bits = [(d >> i) & 1 for d in values for i in range(self.l)]
        return BitDecompositions(self.bits.encrypt_batch(low_bits))

    def tests_count(self) -> int:
        return sum(self.thresholds) * (self.l + 1)

    def zero_test(self, msg: BlindedTests) -> None:
        """Step 4: delta_B = [some c is zero]; every c is tested, no early exit."""
        if not self._high or self._shares:
            raise LocalProtocolError("zero_test follows decompose, once")
        if len(msg.ciphertexts) != self.tests_count():
            raise RemoteProtocolError("wrong number of blinded tests")
        zeros = [self.bits.is_zero(c) for c in msg.ciphertexts]
        group = self.l + 1
        position = 0
        shares = []
        for j, count in enumerate(self.thresholds):
            per = []
            for _ in range(count):
                # An honest Alice's group holds at most one zero.  More is not refused: the
                # refusal would be one more bit of her choice per run; any zero counts once.
                found = any(zeros[position : position + group])
                position += group
                per.append(self._high[j] ^ found)
            shares.append(per)
        self._shares = shares
