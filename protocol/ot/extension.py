"""Random OTs for one run: SoftSpokenOT's subspace VOLE over the cached setup (sans-IO).

For each block b (k bits, N = 2^k leaves s_x) both expand every leaf they know with the run's
PRG, G_x = PRG(s_x, nonce), an M-bit string (M = number of OTs of the run):

* chooser (Bob, knows every leaf): u_b = sum_x G_x and v_b = sum_x x . G_x  (x in F_2^k);
* holder (Alice, all but x = Delta_b): w_b = sum_x (x xor Delta_b) . G_x -- the unknown leaf has
  coefficient 0 -- which equals v_b + Delta_b . u_b.

Bob's random choice bits are c = u_0 and he sends d_b = u_b xor c for b >= 1; Alice adds
Delta_b . d_b.  Now every bit column satisfies w = v + Delta_bit . c, i.e. for each OT i the
kappa-bit rows q_i (Alice) and t_i (Bob) satisfy q_i = t_i xor c_i Delta (IKNP's correlation).
Hashing with a per-run, per-index tweak gives random OTs: Alice K_i^0 = H(i, q_i),
K_i^1 = H(i, q_i xor Delta); Bob c_i and K_i^{c_i} = H(i, t_i).  Bob sends (blocks - 1) M bits.

Why it is private: d_b hides c because u_b contains G at Alice's unknown leaf, a fresh
pseudorandom string (Roy 2022, theorem 5.2, semi-honest); Bob never sees anything from Alice
here, and K_i^{1 - c_i} needs Delta (correlation robustness of H).  The nonce must never repeat
for one setup: the path protocol derives it from both parties' fresh random nonces.

Sums over the 2^k leaves use the halving trick (v_0 from the odd rows, then pair rows and
recurse): about 2 N XORs of M-bit rows per block instead of k N / 2.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot import check
from protocol.ot.hashing import KEY_SIZE, prg, rot_key
from protocol.ot.setup import ChooserSetup, HolderSetup

Bytes = npt.NDArray[np.uint8]
MAX_OTS = 1 << 24


def correction_size(blocks: Sequence[int], count: int) -> int:
    """Bytes of Bob's extension message for ``count`` OTs: the corrections of ``count`` and of
    the check's extra OTs, and the check's reply (:mod:`.check`)."""
    kappa = sum(blocks)
    total = count + check.extra_ots(kappa)
    return (len(blocks) - 1) * ((total + 7) // 8) + check.reply_size(kappa)


def check_bytes(blocks: Sequence[int], count: int) -> int:
    """Of :func:`correction_size`, the bytes of the consistency check (its extra OTs'
    corrections and its reply): what protection against a deviating Bob costs a run."""
    return correction_size(blocks, count) - (len(blocks) - 1) * ((count + 7) // 8)


def _expand(leaves: Sequence[bytes | None], nonce: bytes, nbytes: int) -> Bytes:
    zero = bytes(nbytes)
    raw = b"".join(zero if s is None else prg(s, nonce, nbytes) for s in leaves)
    return np.frombuffer(raw, dtype=np.uint8).reshape(len(leaves), nbytes)


def _fold(rows: Bytes, k: int) -> tuple[Bytes, list[Bytes]]:
    """(sum_x G_x, [sum_{x: bit j of x} G_x for j < k]) over GF(2)."""
    sums: list[Bytes] = []
    current = rows
    for _ in range(k):
        odd = current[1::2]
        sums.append(np.bitwise_xor.reduce(odd, axis=0))
        current = current[0::2] ^ odd
    return current[0], sums


def _mask_tail(vector: Bytes, count: int) -> Bytes:
    """Zero the bits beyond ``count`` in the last byte (little-endian bit order)."""
    out = vector.copy()
    if count % 8:
        out[-1] &= (1 << (count % 8)) - 1
    return out


def _rows(columns: list[Bytes], count: int) -> Bytes:
    """Transpose kappa column bit-vectors of ``count`` bits into ``count`` rows of kappa / 8
    bytes."""
    matrix = np.unpackbits(np.stack(columns), axis=1, bitorder="little")[:, :count]
    return np.packbits(np.ascontiguousarray(matrix.T), axis=1, bitorder="little")


def _tweak(nonce: bytes, index: int) -> bytes:
    return nonce + index.to_bytes(4, "big")


def _check(count: int, nonce: bytes) -> None:
    most = MAX_OTS - check.extra_ots(128)  # room for the check's own OTs
    if not 1 <= count <= most:
        raise LocalProtocolError(f"{count} OTs outside 1..{most}")
    if len(nonce) < 16:
        raise LocalProtocolError("a run nonce has at least 16 bytes")


@dataclass(frozen=True)
class ChooserRots:
    """Bob's random OTs: choice bit c_i and key K_i^{c_i}."""

    choices: tuple[int, ...]
    keys: tuple[bytes, ...]


@dataclass(frozen=True)
class HolderRots:
    """Alice's random OTs: both keys of each."""

    keys0: tuple[bytes, ...]
    keys1: tuple[bytes, ...]


def chooser_extend(setup: ChooserSetup, nonce: bytes, count: int) -> tuple[bytes, ChooserRots]:
    """Bob: ``count`` random OTs and the message d_1 .. d_(B-1) that lets Alice follow, then
    the consistency check's reply (for ``count`` OTs and the check's extra ones)."""
    _check(count, nonce)
    kappa = sum(setup.blocks)
    total = count + check.extra_ots(kappa)
    nbytes = (total + 7) // 8
    columns: list[Bytes] = []
    sums: list[Bytes] = []
    for k, leaves in zip(setup.blocks, setup.leaves, strict=True):
        u, v = _fold(_expand(leaves, nonce, nbytes), k)
        sums.append(_mask_tail(u, total))
        columns += v
    choice = sums[0]
    message = b"".join((u ^ choice).tobytes() for u in sums[1:])
    reply = check.respond(columns, choice, nonce, message, total)
    rows = _rows(columns, count)
    keys = tuple(rot_key(_tweak(nonce, i), rows[i].tobytes()) for i in range(count))
    bits = np.unpackbits(choice, bitorder="little")[:count]
    return message + reply, ChooserRots(tuple(int(b) for b in bits), keys)


def holder_extend(setup: HolderSetup, nonce: bytes, count: int, message: bytes) -> HolderRots:
    """Alice: both keys of each of the ``count`` random OTs, from Bob's message -- once it
    passes the consistency check (:class:`~protocol.errors.ConsistencyError` if not)."""
    _check(count, nonce)
    kappa = sum(setup.blocks)
    total = count + check.extra_ots(kappa)
    nbytes = (total + 7) // 8
    if len(message) != correction_size(setup.blocks, count):
        raise RemoteProtocolError("OT extension message has the wrong size")
    split = (len(setup.blocks) - 1) * nbytes
    body, reply = message[:split], message[split:]
    corrections = np.frombuffer(body, dtype=np.uint8).reshape(len(setup.blocks) - 1, nbytes)
    for row in corrections:
        if not np.array_equal(row, _mask_tail(row, total)):
            raise RemoteProtocolError("padding bits of the OT extension message must be zero")
    columns: list[Bytes] = []
    delta_bits: list[int] = []
    for b, (k, d, leaves) in enumerate(zip(setup.blocks, setup.delta, setup.leaves, strict=True)):
        rows = _expand(leaves, nonce, nbytes)
        permuted = rows[np.arange(1 << k) ^ d]  # row y holds G_(y xor Delta_b); row 0 unknown
        _, w = _fold(permuted, k)
        for j in range(k):
            bit = (d >> j) & 1
            delta_bits.append(bit)
            columns.append(w[j] ^ corrections[b - 1] if b and bit else w[j])
    delta_int = sum(bit << j for j, bit in enumerate(delta_bits))
    check.verify(columns, delta_int, nonce, body, total, reply)
    q = _rows(columns, count)
    delta = np.packbits(np.array(delta_bits, dtype=np.uint8), bitorder="little")
    flipped = q ^ delta
    keys0 = tuple(rot_key(_tweak(nonce, i), q[i].tobytes()) for i in range(count))
    keys1 = tuple(rot_key(_tweak(nonce, i), flipped[i].tobytes()) for i in range(count))
    return HolderRots(keys0, keys1)


__all__ = [
    "KEY_SIZE",
    "ChooserRots",
    "HolderRots",
    "check_bytes",
    "chooser_extend",
    "correction_size",
    "holder_extend",
]
