"""Punctured GGM trees: the holder gets every leaf but its point, and nothing about that one."""

from __future__ import annotations

import secrets

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import RemoteProtocolError
from protocol.ot.pprf import correction_size, expand_full, expand_punctured


@settings(max_examples=40, deadline=None)
@given(depth=st.integers(1, 8), data=st.data())
def test_all_but_the_punctured_leaf(depth: int, data: st.DataObject) -> None:
    point = data.draw(st.integers(0, (1 << depth) - 1))
    pairs = [(secrets.token_bytes(16), secrets.token_bytes(16)) for _ in range(depth)]
    leaves, corrections = expand_full(pairs)
    assert len(leaves) == 1 << depth and len(set(leaves)) == 1 << depth
    assert len(corrections) == correction_size(depth)
    bits = [(point >> (depth - 1 - i)) & 1 for i in range(depth)]
    keys = [pair[1 - bit] for pair, bit in zip(pairs, bits, strict=True)]
    mine = expand_punctured(point, depth, keys, corrections)
    for x, (full, known) in enumerate(zip(leaves, mine, strict=True)):
        assert known is None if x == point else known == full


def test_wrong_choice_gives_wrong_leaves() -> None:
    """With the path side's keys instead, the rebuilt siblings are garbage (negative control)."""
    depth, point = 4, 5
    pairs = [(secrets.token_bytes(16), secrets.token_bytes(16)) for _ in range(depth)]
    leaves, corrections = expand_full(pairs)
    bits = [(point >> (depth - 1 - i)) & 1 for i in range(depth)]
    keys = [pair[bit] for pair, bit in zip(pairs, bits, strict=True)]
    wrong = expand_punctured(point, depth, keys, corrections)
    assert sum(w == f for w, f in zip(wrong, leaves, strict=True)) == 0


def test_corrections_are_strict() -> None:
    pairs = [(secrets.token_bytes(16), secrets.token_bytes(16)) for _ in range(3)]
    _, corrections = expand_full(pairs)
    keys = [p[0] for p in pairs]
    with pytest.raises(RemoteProtocolError):
        expand_punctured(0, 3, keys, corrections + b"\x00")
    with pytest.raises(RemoteProtocolError):
        expand_punctured(0, 3, keys, corrections[:-1])
