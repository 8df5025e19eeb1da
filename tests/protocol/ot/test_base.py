"""Base OTs on secp256k1: the receiver gets exactly the key of its choice."""

from __future__ import annotations

import pytest

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot.base import BaseReceiver, BaseSender, message_size
from protocol.primitives import secp256k1 as ec


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
    """The receiver's points are valid, distinct curve points (x only, even y) whatever the
    choice."""
    zeros, ones = BaseReceiver([0] * 8).message(), BaseReceiver([1] * 8).message()
    for message in (zeros, ones):
        assert len(message) == 8 * ec.X_SIZE
        points = {message[i * 32 : (i + 1) * 32] for i in range(8)}
        assert len(points) == 8 and all(ec.has_even_y(ec.decode_x(p)) for p in points)


def test_strict_decoding() -> None:
    receiver = BaseReceiver([0, 1])
    with pytest.raises(RemoteProtocolError):
        BaseSender(receiver.message()[:-1], 2)
    with pytest.raises(RemoteProtocolError):
        BaseSender(receiver.message() + b"\x00", 2)
    bad = b"\xff" * 32 + receiver.message()[32:]  # x above the field's prime
    with pytest.raises(RemoteProtocolError):
        BaseSender(bad, 2)
    off_curve = next(  # an x with no y: about every other one
        x for x in (k.to_bytes(32, "big") for k in range(1, 100)) if not _on_curve(x)
    )
    with pytest.raises(RemoteProtocolError):
        BaseSender(off_curve + receiver.message()[32:], 2)
    with pytest.raises(RemoteProtocolError):
        receiver.keys(b"\x02" + b"\xff" * 32)  # x not on the curve
    with pytest.raises(LocalProtocolError):
        BaseReceiver([2])


def _on_curve(x: bytes) -> bool:
    try:
        ec.decode_x(x)
    except RemoteProtocolError:
        return False
    return True
