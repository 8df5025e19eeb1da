"""OT extension: random OTs with IKNP's relation, fixed sizes, strict decoding, fresh per nonce."""

from __future__ import annotations

import secrets

import pytest

from protocol.errors import ConsistencyError, LocalProtocolError, RemoteProtocolError
from protocol.ot.check import extra_ots
from protocol.ot.extension import chooser_extend, correction_size, holder_extend
from protocol.ot.setup import (
    DEFAULT_BLOCKS,
    HolderSetupStart,
    check_blocks,
    chooser_message_size,
    chooser_setup,
    holder_message_size,
    split_blocks,
)


def test_blocks_are_split_evenly() -> None:
    assert DEFAULT_BLOCKS == (12, 12) + (11,) * 8  # kappa = 112, at most 12 bits a block
    assert split_blocks(12, 128) == (12,) * 7 + (11,) * 4
    assert split_blocks(8, 112) == (8,) * 14
    for k in range(1, 13):
        for kappa in (112, 128):
            blocks = split_blocks(k, kappa)
            assert sum(blocks) == kappa and max(blocks) == k and max(blocks) - min(blocks) <= 1


@pytest.mark.parametrize(
    "blocks", [DEFAULT_BLOCKS, (4,) * 28, (8,) * 14, (12,) * 10 + (8,), (1,) * 128, (1,) * 112]
)
@pytest.mark.parametrize("count", [1, 7, 8, 9, 1000])
def test_random_ots(blocks: tuple[int, ...], count: int) -> None:
    start = HolderSetupStart(blocks)
    assert len(start.message()) == holder_message_size(sum(blocks))
    chooser, reply = chooser_setup(start.message(), blocks)
    assert len(reply) == chooser_message_size(blocks)
    holder = start.finish(reply)
    assert holder.setup_id == chooser.setup_id
    nonce = secrets.token_bytes(32)
    message, bob = chooser_extend(chooser, nonce, count)
    assert len(message) == correction_size(blocks, count)
    alice = holder_extend(holder, nonce, count, message)
    for c, key, k0, k1 in zip(bob.choices, bob.keys, alice.keys0, alice.keys1, strict=True):
        assert key == (k0, k1)[c] != (k0, k1)[1 - c]
    if count >= 1000:
        assert 400 < sum(bob.choices) < 600  # random choice bits


def test_each_nonce_gives_fresh_ots(ot_pair) -> None:  # type: ignore[no-untyped-def]
    first = chooser_extend(ot_pair.chooser, secrets.token_bytes(32), 64)
    second = chooser_extend(ot_pair.chooser, secrets.token_bytes(32), 64)
    assert first[0] != second[0]
    assert not set(first[1].keys) & set(second[1].keys)


def test_strictness(ot_pair) -> None:  # type: ignore[no-untyped-def]
    nonce = secrets.token_bytes(32)
    message, _ = chooser_extend(ot_pair.chooser, nonce, 13)
    with pytest.raises(RemoteProtocolError):
        holder_extend(ot_pair.holder, nonce, 13, message[:-1])
    tampered = bytearray(message)
    row = (13 + extra_ots(112) + 7) // 8  # 13 OTs and the check's extra ones
    tampered[row - 1] |= 0x80  # a padding bit beyond them in the first correction row
    with pytest.raises(RemoteProtocolError, match="padding"):
        holder_extend(ot_pair.holder, nonce, 13, bytes(tampered))
    with pytest.raises(LocalProtocolError):
        chooser_extend(ot_pair.chooser, b"short", 13)
    with pytest.raises(LocalProtocolError):
        check_blocks((8,) * 15)  # 120 bits: neither 112 nor 128
    with pytest.raises(LocalProtocolError):
        check_blocks((13,) * 8 + (8,))  # blocks of more than 12 bits
    with pytest.raises(RemoteProtocolError):  # points for 112 OTs, blocks for 128
        chooser_setup(HolderSetupStart(DEFAULT_BLOCKS).message(), split_blocks(12, 128))
    with pytest.raises(RemoteProtocolError):
        chooser_setup(b"\x02" * 10, DEFAULT_BLOCKS)


def test_a_mismatched_nonce_fails_the_check(ot_pair) -> None:  # type: ignore[no-untyped-def]
    """Negative control: the relation holds only for the same run nonce, and the consistency
    check sees it before any key is made."""
    message, _ = chooser_extend(ot_pair.chooser, secrets.token_bytes(32), 200)
    with pytest.raises(ConsistencyError):
        holder_extend(ot_pair.holder, secrets.token_bytes(32), 200, message)
