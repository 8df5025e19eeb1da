"""Sender and receiver state without I/O: fragmentation, reassembly, ACKs, bounds."""

from __future__ import annotations

import random
import secrets

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.radio.arq import LinkTimeout, MessageTooLarge, Outgoing
from companion.radio.frames import Flag, Frame, FrameType, decode_frame
from companion.radio.reassembly import Receiver


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
    assert receiver.stats.refused["evicted"] == 6  # the oldest forged ones made room


def test_a_flood_of_first_fragments_evicts_only_the_untrusted() -> None:
    """Partial messages of trusted sessions (ours, authenticated) stay whatever a flood of
    forged first fragments brings; an untrusted message whose fragments keep coming is the
    last of the untrusted to go; when only trusted partials are held a newcomer is refused."""
    receiver = Receiver(2, max_partial=4)
    receiver.trust(1, 7)
    mine = Outgoing(1, 2, 7, 0, bytes(300), 100)
    theirs = Outgoing(3, 2, 9, 0, bytes(300), 100)
    first, second, third = mine.burst()
    receiver.on_frame(first, 0.0)
    forged = (Frame(FrameType.DATA, 100 + k, 2, 5, 0, 0, 200, b"x") for k in range(1000))
    for k in range(50):  # forged first fragments of made-up messages, from made-up nodes
        receiver.on_frame(next(forged), 1.0 + k)
    assert receiver.on_frame(second, 60.0)[0] is None
    delivered, _ = receiver.on_frame(third, 61.0)
    assert delivered is not None and delivered.data == bytes(300)
    # An untrusted message (a request not yet checked) survives forged frames between its
    # fragments as long as fewer than max_partial of them fit between two of its fragments.
    t = 100.0
    delivered = None
    for fragment in theirs.burst():
        t += 0.1
        delivered = receiver.on_frame(fragment, t)[0] or delivered
        for _ in range(3):
            t += 0.1
            receiver.on_frame(next(forged), t)
    assert delivered is not None and delivered.data == bytes(300)
    full = Receiver(2, max_partial=2)
    for session in (1, 2):
        full.trust(1, session)
        full.on_frame(Frame(FrameType.DATA, 1, 2, session, 0, 0, 3, b"x"), 0.0)
    assert full.on_frame(Frame(FrameType.DATA, 9, 2, 1, 0, 0, 3, b"x"), 1.0) == (None, None)
    assert full.pending() == 2 and full.stats.refused["too_many_partial"] == 1


def test_remembered_streams_are_bounded() -> None:
    receiver = Receiver(2, max_streams=8)
    receiver.trust(1, 1)
    receiver.on_frame(Frame(FrameType.DATA, 1, 2, 1, 0, 0, 1, b"m"), 0.0)
    for k in range(100):  # forged one-frame messages, each a stream of its own
        receiver.on_frame(Frame(FrameType.DATA, 100 + k, 2, 5, 0, 0, 1, b"x"), 1.0 + k)
    streams = receiver.streams()
    assert len(streams) == 8 and (1, 1) in streams


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
    # The peer restarted: it holds nothing ... A restarted receiver counts its epochs from a
    # random start, which is the old epoch once in 255 restarts (companion.radio.reassembly);
    # here it is one the sender has not seen.
    fresh = Receiver(2, epoch=out.epoch if out.epoch is not None else 1)
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


def test_a_delivered_message_is_remembered_while_its_session_is_alive() -> None:
    """The sender may stay silent about an unacknowledged message for longer than the idle
    timeout (its peer is busy sending a long reply in the session).  Its next probe must get
    COMPLETE, not open a new copy that would deliver the message a second time."""
    receiver = Receiver(2, idle_timeout=10.0)
    out = Outgoing(1, 2, 7, 0, bytes(500), 100)
    burst = out.burst()
    for frame in burst:
        message, ack = receiver.on_frame(frame, 0.0)
    assert message is not None  # the COMPLETE ack is lost
    last = burst[-1]  # fragment 4, asking for an ACK
    assert last.index == 4 and last.flags & Flag.ACK_REQ
    for now in (8.0, 16.0, 24.0):
        receiver.touch(1, 7, now)  # other frames of session 7 (e.g. ACKs of the reply)
        receiver.expire(now)
    message, ack = receiver.on_frame(out.probe(), 30.0)  # the sender polls at last
    assert message is None and ack is not None and ack.flags & Flag.COMPLETE
    message, ack = receiver.on_frame(last, 31.0)
    assert message is None and ack is not None and ack.flags & Flag.COMPLETE
    assert receiver.pending() == 0
    receiver.expire(41.0)  # a session silent for the idle timeout is forgotten
    message, ack = receiver.on_frame(last, 42.0)
    assert message is None and ack is not None and not ack.flags & Flag.COMPLETE


def test_delivery_is_in_order_and_older_messages_are_stale() -> None:
    receiver = Receiver(2)
    first = Outgoing(1, 2, 7, 0, bytes(300), 100)
    second = Outgoing(1, 2, 7, 1, b"second", 100)
    third = Outgoing(1, 2, 7, 2, b"third", 100)
    a, b, c = first.burst()
    receiver.on_frame(a, 0.0)  # the sender gave up on message 0 (cancelled) ...
    (frame,) = second.burst()
    message, _ = receiver.on_frame(frame, 1.0)  # ... and sent message 1
    assert message is not None and message.data == b"second"
    assert receiver.pending() == 0  # message 0 is stale now: its partial copy is freed
    for frame in (b, c, a):
        assert receiver.on_frame(frame, 2.0) == (None, None)  # never delivered out of order
    message, ack = receiver.on_frame(second.probe(), 3.0)
    assert message is None and ack is not None and ack.flags & Flag.COMPLETE
    (frame,) = third.burst()
    message, _ = receiver.on_frame(frame, 4.0)
    assert message is not None and message.data == b"third"
    assert receiver.on_frame(Frame(FrameType.POLL, 1, 2, 7, 1, 0, 1), 5.0) == (None, None)


def test_sequence_numbers_wrap_around() -> None:
    receiver = Receiver(2)
    got = []
    for n in range(600):
        (frame,) = Outgoing(1, 2, 7, n % 256, n.to_bytes(2, "big"), 100).burst()
        message, ack = receiver.on_frame(frame, float(n))
        assert message is not None and ack is not None and ack.flags & Flag.COMPLETE
        got.append(int.from_bytes(message.data, "big"))
        assert receiver.on_frame(frame, float(n))[0] is None  # a copy is not delivered again
    assert got == list(range(600))


def test_a_copy_begun_again_never_reuses_the_epoch(monkeypatch: pytest.MonkeyPatch) -> None:
    """Epochs were drawn at random per copy: once in 255 restarts the new copy had the old
    epoch, the sender trusted its stale acknowledgements and the message was lost."""
    monkeypatch.setattr(secrets, "randbelow", lambda n: 41)  # every draw the same
    receiver = Receiver(2, idle_timeout=10.0)
    out = Outgoing(1, 2, 7, 0, bytes(range(250)) * 2, 100)
    for frame in out.burst()[:4]:
        receiver.on_frame(frame, 0.0)
    _, ack = receiver.on_frame(out.probe(), 1.0)
    assert ack is not None and out.on_ack(ack)
    assert out.acked == [True, True, True, True, False]
    assert receiver.expire(11.0) == 1  # the copy is dropped (the sender was silent) ...
    message, ack = receiver.on_frame(out.burst()[0], 12.0)  # ... and begun again
    assert message is None and ack is not None and out.on_ack(ack)
    assert out.restarts == 1 and not out.complete  # the sender saw the new epoch
    for frame in out.burst():
        message, ack = receiver.on_frame(frame, 13.0)
    assert message is not None and message.data == bytes(range(250)) * 2
