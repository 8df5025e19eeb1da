"""Base OTs on secp256k1: the receiver gets exactly the key of its choice."""

from __future__ import annotations

import pytest

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot.base import BaseReceiver, BaseSender, message_size


def test_receiver_gets_the_chosen_key_only() -> None:
    choices = [i % 2 for i in range(20)] + [1, 1, 0]
    receiver = BaseReceiver(choices)
    assert len(receiver.message()) == message_size(len(choices))
    sender = BaseSender(receiver.message(), len(choices))
    keys = receiver.keys(sender.message())
    for c, k, (k0, k1) in zip(choices, keys, sender.keys, strict=True):
        assert k == (k0, k1)[c]
        assert k != (k0, k1)[1 - c]
        assert len(k) == 16


def test_points_look_the_same_for_either_choice() -> None:
    """The receiver's points are valid, distinct curve points whatever the choice."""
    zeros, ones = BaseReceiver([0] * 8).message(), BaseReceiver([1] * 8).message()
    for message in (zeros, ones):
        points = {message[i * 33 : (i + 1) * 33] for i in range(8)}
        assert len(points) == 8 and all(p[0] in (2, 3) for p in points)


def test_strict_decoding() -> None:
    receiver = BaseReceiver([0, 1])
    with pytest.raises(RemoteProtocolError):
        BaseSender(receiver.message()[:-1], 2)
    with pytest.raises(RemoteProtocolError):
        BaseSender(receiver.message() + b"\x00", 2)
    bad = bytearray(receiver.message())
    bad[0] = 4
    with pytest.raises(RemoteProtocolError):
        BaseSender(bytes(bad), 2)
    with pytest.raises(RemoteProtocolError):
        receiver.keys(b"\x02" + b"\xff" * 32)  # x not on the curve
    with pytest.raises(LocalProtocolError):
        BaseReceiver([2])
