"""The symmetric primitives under the OT layer, each in its own domain (random-oracle model).

* :func:`prg` -- SHAKE128: a 16-byte seed and a run nonce to as many bytes as needed.
* :func:`ggm_children` -- BLAKE2b: the two children of a GGM tree node (Goldreich, Goldwasser,
  Micali 1986).
* :func:`rot_key` -- BLAKE2b as the tweakable correlation-robust hash H(i, q) that turns
  correlated OT into random OT (IKNP, section 3): the tweak is the run nonce and OT index, so a
  row is never hashed twice under the same tweak.
* :func:`pad` -- BLAKE2b (SHAKE128 beyond 64 bytes) over OT keys and a label: one-time
  pads of any bit width for the messages
  sent under random OTs.

Every key and seed is :data:`KEY_SIZE` = 16 bytes (128-bit security).
"""

from __future__ import annotations

import hashlib

KEY_SIZE = 16


def prg(seed: bytes, nonce: bytes, nbytes: int) -> bytes:
    """Pseudorandom bytes from ``seed`` for the run ``nonce``."""
    return hashlib.shake_128(b"pdc/ot/prg/v1" + seed + nonce).digest(nbytes)


def ggm_children(node: bytes) -> tuple[bytes, bytes]:
    """Left and right child of a GGM node."""
    out = hashlib.blake2b(node, digest_size=2 * KEY_SIZE, person=b"pdc/ot/ggm/v1").digest()
    return out[:KEY_SIZE], out[KEY_SIZE:]


def rot_key(tweak: bytes, row: bytes) -> bytes:
    """H(tweak, row): a random-OT key from an IKNP row (``tweak`` = nonce and index)."""
    return hashlib.blake2b(tweak + row, digest_size=KEY_SIZE, person=b"pdc/ot/rot/v1").digest()


def pad(keys: bytes, label: bytes, nbits: int) -> int:
    """An ``nbits``-bit one-time pad from OT key material and a public label."""
    nbytes = (nbits + 7) // 8
    if nbytes <= 64:
        raw = hashlib.blake2b(keys + label, digest_size=nbytes, person=b"pdc/ot/pad/v1").digest()
    else:
        raw = hashlib.shake_128(b"pdc/ot/pad/v1" + keys + label).digest(nbytes)
    return int.from_bytes(raw, "big") >> (8 * nbytes - nbits)


def base_key(index: int, *points: bytes) -> bytes:
    """Key of base OT ``index`` from the encoded points of its Diffie-Hellman exchange."""
    h = hashlib.blake2b(digest_size=KEY_SIZE, person=b"pdc/ot/base/v1")
    h.update(index.to_bytes(2, "big"))
    for point in points:
        h.update(point)
    return h.digest()
