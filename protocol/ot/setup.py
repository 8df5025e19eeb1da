"""The one-time OT setup between two drones: base OTs, then punctured trees (cached per peer).

The secret Delta of the holder (Alice) has kappa bits (the computational security parameter
of the OT extension: 112 by default, the project's level, as ABY's "medium term" setting; 128
on request) and is cut into blocks of at most 12 bits (default for 112: two of 12 bits and
eight of 11, see :data:`DEFAULT_BLOCKS`); block b has a GGM tree of depth k_b whose punctured
point is Delta_b.  kappa base OTs (one per bit of Delta, :mod:`.base`) carry the tree levels.

Messages (both ride on the path protocol's first two messages, so a setup costs no round trip):

* holder -> chooser: the base-OT receiver points, 32 bytes (x only) x kappa;
* chooser -> holder: A (32 bytes), then the level corrections of every tree (32 bytes per level
  below the first).

Both ends name the result by ``setup_id`` = BLAKE2b(A || points), 16 bytes, and keep it for the
next runs with the same peer (:mod:`.extension`).
"""

from __future__ import annotations

import hashlib
import secrets
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot.base import BaseReceiver, BaseSender
from protocol.ot.pprf import correction_size, expand_full, expand_punctured
from protocol.primitives import secp256k1 as ec
from protocol.wire.encoding import Reader

SECURITY_LEVELS = (112, 128)  # kappa: bits of Delta = base OTs
DEFAULT_SECURITY = 112
DEFAULT_BLOCK_BITS = 12  # chosen on measurements: ``python -m protocol bench design``
SETUP_ID_SIZE = 16
MAX_BLOCK_BITS = 12


def split_blocks(block_bits: int, security: int = DEFAULT_SECURITY) -> tuple[int, ...]:
    """kappa bits of Delta in as few blocks of at most ``block_bits`` as possible, sizes as
    even as possible (the work of a block grows as 2^k; its bytes do not depend on k)."""
    if not 1 <= block_bits <= MAX_BLOCK_BITS:
        raise LocalProtocolError(f"OT blocks of {block_bits} bits are not supported")
    count = -(-security // block_bits)
    size, extra = divmod(security, count)
    return check_blocks((size + 1,) * extra + (size,) * (count - extra))


def check_blocks(blocks: Sequence[int]) -> tuple[int, ...]:
    blocks = tuple(blocks)
    if sum(blocks) not in SECURITY_LEVELS or not all(1 <= k <= MAX_BLOCK_BITS for k in blocks):
        raise LocalProtocolError(
            f"blocks must be 1..{MAX_BLOCK_BITS} bits each and add up to one of {SECURITY_LEVELS}"
        )
    return blocks


DEFAULT_BLOCKS = split_blocks(DEFAULT_BLOCK_BITS)


def describe(blocks: Sequence[int]) -> str:
    """E.g. "SoftSpokenOT, 112-bit Delta in 10 blocks (2 x 12 bits, 8 x 11)"."""
    sizes = sorted(set(blocks), reverse=True)
    parts = ", ".join(
        f"{list(blocks).count(k)} x {k}" + (" bits" if i == 0 else "") for i, k in enumerate(sizes)
    )
    return f"SoftSpokenOT, {sum(blocks)}-bit Delta in {len(blocks)} blocks ({parts})"


def holder_message_size(security: int = DEFAULT_SECURITY) -> int:
    return security * ec.X_SIZE


def chooser_message_size(blocks: Sequence[int]) -> int:
    return ec.X_SIZE + sum(correction_size(k) for k in blocks)


def _setup_id(a_point: bytes, points: bytes) -> bytes:
    return hashlib.blake2b(
        a_point + points, digest_size=SETUP_ID_SIZE, person=b"pdc/ot/setup/v1"
    ).digest()


@dataclass(frozen=True)
class ChooserSetup:
    """Bob's cached state: every leaf of every tree."""

    setup_id: bytes
    blocks: tuple[int, ...]
    leaves: tuple[tuple[bytes, ...], ...]


@dataclass(frozen=True)
class HolderSetup:
    """Alice's cached state: Delta and every leaf but the punctured one of each tree."""

    setup_id: bytes
    blocks: tuple[int, ...]
    delta: tuple[int, ...]  # Delta_b per block
    leaves: tuple[tuple[bytes | None, ...], ...]


class HolderSetupStart:
    """Alice's first half: a fresh Delta and the base-OT receiver message."""

    def __init__(self, blocks: Sequence[int] = DEFAULT_BLOCKS) -> None:
        self.blocks = check_blocks(blocks)
        self.delta = tuple(secrets.randbits(k) for k in self.blocks)
        choices = [
            1 - ((d >> (k - 1 - i)) & 1)
            for d, k in zip(self.delta, self.blocks, strict=True)
            for i in range(k)
        ]
        self._receiver = BaseReceiver(choices)
        self._points = self._receiver.message()

    def message(self) -> bytes:
        return self._points

    def finish(self, reply: bytes) -> HolderSetup:
        """Read the chooser's A and corrections; the holder's trees."""
        reader = Reader(reply)
        a_point = reader.take(ec.X_SIZE)
        keys = self._receiver.keys(a_point)
        leaves = []
        used = 0
        for d, k in zip(self.delta, self.blocks, strict=True):
            corrections = reader.take(correction_size(k))
            leaves.append(tuple(expand_punctured(d, k, keys[used : used + k], corrections)))
            used += k
        reader.finish()
        return HolderSetup(_setup_id(a_point, self._points), self.blocks, self.delta, tuple(leaves))


def chooser_setup(holder_message: bytes, blocks: Sequence[int]) -> tuple[ChooserSetup, bytes]:
    """Bob: his trees and the reply (A, corrections) from Alice's base-OT points."""
    blocks = check_blocks(blocks)
    if len(holder_message) != holder_message_size(sum(blocks)):
        raise RemoteProtocolError("OT setup message has the wrong size")
    sender = BaseSender(holder_message, sum(blocks))
    leaves = []
    corrections = []
    used = 0
    for k in blocks:
        nodes, fix = expand_full(sender.keys[used : used + k])
        leaves.append(tuple(nodes))
        corrections.append(fix)
        used += k
    a_point = sender.message()
    setup = ChooserSetup(_setup_id(a_point, holder_message), blocks, tuple(leaves))
    return setup, a_point + b"".join(corrections)
