"""Several channels of a region (issue 29): a session's call on the common channel, the rest
on a channel of its own, one transceiver per node, on a virtual clock."""

from __future__ import annotations

import asyncio

import pytest

from companion.radio import PROFILES, Clock, LinkConfig, LinkEndpoint
from companion.radio.arq import PeerElsewhere
from companion.radio.endpoint import CALL, CALL_WAIT_S
from companion.radio.frames import Flag, Frame, FrameType
from companion.sim.medium import Channel, Impairments, SimMedium
from companion.sim.virtual_time import run_simulated

US915 = PROFILES["us915-sf7"]


async def _two_pairs(channels: int, loss: float) -> tuple[float, list[bytes]]:
    """Two pairs, each a request, a long answer, a long message and a short answer: when
    the last message arrived (link seconds), and what the Alices received."""
    clock = Clock()
    medium = SimMedium(Channel(Impairments(loss=loss), 3), clock)
    config = LinkConfig(channels=channels)
    nodes = [LinkEndpoint(i, medium.attach(i), US915, config, clock) for i in range(1, 5)]
    for node in nodes:
        await node.start()

    async def alice(a: LinkEndpoint, b: int) -> bytes:
        session = a.open(b)
        await a.send(b, session, b"r" * 300)
        first = await a.receive(b, session)
        await a.send(b, session, b"m" * 3000)
        last = await a.receive(b, session)
        a.close_session(b, session)
        return first + last

    async def bob(b: LinkEndpoint) -> None:
        peer, session = await b.accept()
        request = await b.receive(peer, session)
        await b.send(peer, session, request[:1] * 3000)
        message = await b.receive(peer, session)
        await b.send(peer, session, message[:1] * 500)
        await clock.sleep(10)  # (its ACK may be lost: answer the copies)
        b.close_session(peer, session)

    got = await asyncio.gather(alice(nodes[0], 2), alice(nodes[2], 4), bob(nodes[1]), bob(nodes[3]))
    end = clock.now()
    for node in nodes:
        await node.close()
    return end, [g for g in got if g is not None]


def test_two_pairs_on_their_own_channels_run_side_by_side() -> None:
    one, got_one = run_simulated(_two_pairs(1, 0.1))
    many, got_many = run_simulated(_two_pairs(8, 0.1))
    assert got_one == got_many == [b"r" * 3000 + b"m" * 500] * 2
    # one channel: the two pairs take turns on the air; eight: each has its own
    # (measured 8 runs each, 2026-12-04: 37.9-39.0 s against 25.3-26.6 s, the bobs' 10 s
    # wait included)
    assert many < one - 6.0


def test_a_call_nobody_follows_gives_the_common_channel_back() -> None:
    """A stranger's call moves a drone to a session's channel for CALL_WAIT_S at most: it is
    deaf to the common channel no longer than that."""

    async def main() -> tuple[bool, bool, int]:
        clock = Clock()
        medium = SimMedium(Channel(), clock)
        config = LinkConfig(channels=8)
        bob = LinkEndpoint(2, medium.attach(2), US915, config, clock)
        stranger = medium.attach(9)
        await bob.start()
        frame = Frame(FrameType.DATA, 9, 2, 77, 0, 0, 1, CALL, Flag.ACK_REQ)
        await stranger.transmit(frame.encode(), US915.airtime(len(frame.encode())))
        await clock.sleep(1.0)
        moved = medium.channel.tuned.get(2, (0, 0.0))[0] != 0
        await clock.sleep(CALL_WAIT_S)
        back = medium.channel.tuned.get(2, (0, 0.0))[0] == 0
        dropped = bob.stats.dropped.get("unanswered_call", 0)
        await bob.close()
        return moved, back, dropped

    moved, back, dropped = run_simulated(main())
    assert moved and back and dropped == 1


def test_a_peer_in_a_run_elsewhere_is_told_quickly() -> None:
    """Node 2 is in its own run with node 4, on node 4's channel: node 3's call to it goes
    unanswered and fails as PeerElsewhere (what BUSY says on one channel) within seconds,
    not after the twenty backed-off probes of a vanished peer.  (A call to a node busy on
    its own channel is heard there: it waits its turn, as on one channel.)"""

    async def main() -> tuple[type[BaseException] | None, float]:
        clock = Clock()
        medium = SimMedium(Channel(), clock)
        config = LinkConfig(channels=8)
        busy, other, caller = (
            LinkEndpoint(i, medium.attach(i), US915, config, clock) for i in (2, 4, 3)
        )
        for node in (busy, other, caller):
            await node.start()
        s1 = busy.open(4)
        await busy.send(4, s1, b"first")  # node 2 is now on node 4's channel
        peer, session = await other.accept()
        assert (peer, await other.receive(peer, session)) == (2, b"first")
        start = clock.now()
        s2 = caller.open(2)
        error: type[BaseException] | None = None
        try:
            await caller.send(2, s2, b"second")
        except PeerElsewhere as exc:
            error = type(exc)
        took = clock.now() - start
        for node in (busy, other, caller):
            await node.close()
        return error, took

    error, took = run_simulated(main())
    assert error is PeerElsewhere and took < 20.0


def test_more_channels_than_the_region_has_are_refused() -> None:
    medium = SimMedium(Channel(), Clock())
    with pytest.raises(ValueError, match="channels"):
        LinkEndpoint(1, medium.attach(1), PROFILES["eu868-g3-sf7"], LinkConfig(channels=2))
    assert PROFILES["us915-sf7"].channels == 8 and PROFILES["eu868-sf7"].channels == 3
