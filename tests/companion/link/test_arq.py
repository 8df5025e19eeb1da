"""Sender and receiver state without I/O: fragmentation, reassembly, ACKs, bounds."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.link.arq import LinkTimeout, MessageTooLarge, Outgoing
from companion.link.frames import Flag, Frame, FrameType, decode_frame
from companion.link.reassembly import Receiver


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=3000), st.integers(8, 200), st.randoms(use_true_random=False))
def test_any_order_with_duplicates_delivers_once(
    data: bytes, size: int, rng: random.Random
) -> None:
    out = Outgoing(1, 2, 7, 0, data, size, window=1000)
    frames = out.burst()
    shuffled = frames + rng.sample(frames, k=min(len(frames), 5))
    rng.shuffle(shuffled)
    receiver = Receiver(2)
    delivered = []
    for frame in shuffled:
        message, _ = receiver.on_frame(decode_frame(frame.encode()), 0.0)
        if message is not None:
            delivered.append(message.data)
    assert delivered == [data]
    assert receiver.pending() == 0


def test_selective_repeat_sends_only_the_missing() -> None:
    out = Outgoing(1, 2, 7, 3, bytes(1000), 100, window=64)
    receiver = Receiver(2)
    first = out.burst()
    assert len(first) == 10 and first[-1].flags & Flag.ACK_REQ
    ack = None
    for frame in first:
        if frame.index in (2, 9):
            continue  # lost, including the one that asked for the ACK
        _, ack = receiver.on_frame(frame, 0.0)
    assert ack is None  # nobody asked
    _, ack = receiver.on_frame(out.probe(), 1.0)  # a POLL after the timeout
    assert ack is not None and ack.type is FrameType.ACK
    out.on_ack(ack)
    again = out.burst()
    assert [f.index for f in again] == [2, 9]
    for frame in again:
        message, ack = receiver.on_frame(frame, 2.0)
    assert message is not None and message.data == bytes(1000)
    assert ack is not None and ack.flags & Flag.COMPLETE
    out.on_ack(ack)
    assert out.complete and out.retransmissions == 2


def test_retries_are_bounded() -> None:
    out = Outgoing(1, 2, 7, 0, b"x" * 50, 20, max_tries=3, max_polls=2)
    for _ in range(3):
        out.burst()
    with pytest.raises(LinkTimeout, match="after 3 transmissions"):
        out.burst()
    single = Outgoing(1, 2, 7, 0, b"x" * 50, 20, max_polls=2)
    single.burst()
    single.probe()
    single.probe()
    with pytest.raises(LinkTimeout, match="silent after 2 probes"):
        single.probe()


def test_single_outstanding_fragment_is_its_own_probe() -> None:
    out = Outgoing(1, 2, 7, 0, b"hello", 100)
    (frame,) = out.burst()
    probe = out.probe()
    assert probe.type is FrameType.DATA and probe.index == frame.index
    assert probe.flags & Flag.ACK_REQ


def test_message_size_bounds() -> None:
    with pytest.raises(MessageTooLarge):
        Outgoing(1, 2, 7, 0, bytes(70_000), 1)
    receiver = Receiver(2, max_message=100)
    big = Outgoing(1, 2, 7, 0, bytes(300), 60, window=1000)
    for frame in big.burst():
        message, _ = receiver.on_frame(frame, 0.0)
        assert message is None
    assert receiver.stats.refused.get("too_large", 0) >= 1
    assert receiver.buffered_bytes <= 100


def test_incomplete_messages_expire_and_free_memory() -> None:
    receiver = Receiver(2, idle_timeout=10.0)
    out = Outgoing(1, 2, 7, 0, bytes(500), 100)
    for frame in out.burst()[:3]:
        receiver.on_frame(frame, 0.0)
    assert receiver.pending() == 1 and receiver.buffered_bytes == 300
    assert receiver.expire(5.0) == 0
    assert receiver.expire(10.0) == 1
    assert receiver.pending() == 0 and receiver.buffered_bytes == 0


def test_a_poll_keeps_a_partial_message_alive() -> None:
    receiver = Receiver(2, idle_timeout=10.0)
    out = Outgoing(1, 2, 7, 0, bytes(500), 100)
    receiver.on_frame(out.burst()[0], 0.0)
    receiver.on_frame(Frame(FrameType.POLL, 1, 2, 7, 0, 0, out.count), 8.0)
    assert receiver.expire(12.0) == 0


def test_forged_counts_allocate_nothing_and_partials_are_bounded() -> None:
    receiver = Receiver(2, max_partial=4)
    for seq in range(10):
        frame = Frame(FrameType.DATA, 1, 2, 7, seq, 0, 0xFFFF, b"x")
        receiver.on_frame(frame, 0.0)
    assert receiver.pending() == 4 and receiver.buffered_bytes == 4
    assert receiver.stats.refused["too_many_partial"] == 6


def test_finished_messages_answer_late_polls_with_complete() -> None:
    receiver = Receiver(2)
    out = Outgoing(1, 2, 7, 0, b"abc", 100)
    (frame,) = out.burst()
    message, _ = receiver.on_frame(frame, 0.0)
    assert message is not None
    receiver.forget_session(1, 7)
    message, ack = receiver.on_frame(Frame(FrameType.POLL, 1, 2, 7, 0, 0, 1), 1.0)
    assert message is None and ack is not None and ack.flags & Flag.COMPLETE
    message, _ = receiver.on_frame(frame, 2.0)  # a late copy is not delivered twice
    assert message is None and receiver.stats.duplicates == 1


def test_a_receiver_that_lost_the_message_gets_it_again() -> None:
    out = Outgoing(1, 2, 7, 0, bytes(500), 100)
    receiver = Receiver(2)
    for frame in out.burst():
        if frame.index < 4:
            receiver.on_frame(frame, 0.0)
    _, ack = receiver.on_frame(out.probe(), 1.0)
    assert ack is not None
    out.on_ack(ack)
    assert out.acked == [True, True, True, True, False]
    fresh = Receiver(2)  # the peer restarted: it holds nothing ...
    _, empty = fresh.on_frame(Frame(FrameType.POLL, 1, 2, 7, 0, 0, out.count), 2.0)
    assert empty is not None
    out.on_ack(empty)  # ... which alone might be a stale answer: nothing changes
    assert out.acked[:4] == [True] * 4
    message, ack = fresh.on_frame(out.burst()[0], 3.0)  # the last fragment, to the new copy
    assert message is None and ack is not None
    out.on_ack(ack)  # a new epoch: start over
    assert out.restarts == 1 and out.acked == [False, False, False, False, True]
    for frame in out.burst():
        message, ack = fresh.on_frame(frame, 4.0)
    assert message is not None and message.data == bytes(500)
