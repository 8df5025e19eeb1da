"""Punctured GGM trees: all-but-one OT from one base OT per level.

A tree of depth k has 2^k leaves.  The *chooser* (Bob) knows the whole tree; the *holder*
(Alice) learns every leaf except the one at her secret point p (k bits, most significant
first) and nothing about that leaf.  Level 1 is the pair of keys of the first base OT itself;
below it every node has the children :func:`~.hashing.ggm_children` of its parent.  For each
level i >= 2 the chooser sends the XOR of all left children and of all right children, each
padded with one key of base OT i; the holder chose the key on the side of the sibling of her
path (choice 1 - p_i), so she rebuilds that sibling from the XOR and the children she can
compute, and learns nothing on the path side (Boyle, Gilboa, Ishai, CCS 2016 / SoftSpokenOT,
section 4).  Corrections: 2 x 16 bytes per level below the first.
"""

from __future__ import annotations

from collections.abc import Sequence

from protocol.errors import LocalProtocolError
from protocol.ot.hashing import KEY_SIZE, ggm_children
from protocol.wire.encoding import Reader


def _xor(a: bytes, b: bytes) -> bytes:
    return (int.from_bytes(a, "big") ^ int.from_bytes(b, "big")).to_bytes(KEY_SIZE, "big")


def _xor_all(items: Sequence[bytes]) -> bytes:
    acc = 0
    for item in items:
        acc ^= int.from_bytes(item, "big")
    return acc.to_bytes(KEY_SIZE, "big")


def correction_size(depth: int) -> int:
    return 2 * KEY_SIZE * (depth - 1)


def expand_full(level_keys: Sequence[tuple[bytes, bytes]]) -> tuple[list[bytes], bytes]:
    """Chooser: the 2^k leaves and the level corrections, from the base OT key pairs."""
    if not level_keys:
        raise LocalProtocolError("a GGM tree needs at least one level")
    nodes = list(level_keys[0])
    corrections: list[bytes] = []
    for k0, k1 in level_keys[1:]:
        children = [child for node in nodes for child in ggm_children(node)]
        corrections += [_xor(_xor_all(children[0::2]), k0), _xor(_xor_all(children[1::2]), k1)]
        nodes = children
    return nodes, b"".join(corrections)


def expand_punctured(
    point: int, depth: int, keys: Sequence[bytes], corrections: bytes
) -> list[bytes | None]:
    """Holder: every leaf but ``point``'s (None there).  ``keys[i]`` is the key of base OT
    i + 1, received with choice 1 - (bit i of ``point``, most significant first)."""
    if len(keys) != depth or not 0 <= point < 1 << depth:
        raise LocalProtocolError("punctured tree parameters do not match")
    reader = Reader(corrections)
    bits = [(point >> (depth - 1 - i)) & 1 for i in range(depth)]
    nodes: list[bytes | None] = [None, None]
    nodes[1 - bits[0]] = keys[0]
    for level in range(1, depth):
        side = 1 - bits[level]
        pads = (reader.take(KEY_SIZE), reader.take(KEY_SIZE))
        prefix = point >> (depth - level)  # the path's node on the level above
        children: list[bytes | None] = [None] * (2 * len(nodes))
        for x, node in enumerate(nodes):
            if node is not None:
                children[2 * x], children[2 * x + 1] = ggm_children(node)
        known = [c for c in children[side::2] if c is not None]
        children[2 * prefix + side] = _xor(_xor(pads[side], keys[level]), _xor_all(known))
        nodes = children
    reader.finish()
    return nodes
