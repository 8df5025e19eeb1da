"""Reliable messages over the simulated channel, on a virtual clock."""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Callable

import pytest

from companion.radio import (
    PROFILES,
    Clock,
    LinkConfig,
    LinkEndpoint,
    LinkError,
    LinkTimeout,
    MessageTooLarge,
    PeerAborted,
)
from companion.radio.endpoint import ENGAGED_CYCLES, GONE_CHECK_S, GONE_QUIET_S
from companion.radio.frames import AbortCode, FrameType, decode_frame
from companion.sim.medium import Channel, Impairments, SimMedium, SimTransport
from companion.sim.virtual_time import SimulationStalled, run_simulated
from tests.companion.radio.helpers import pair

HARSH = Impairments(loss=0.3, corrupt=0.05, duplicate=0.05, reorder=0.1)


async def _echo(p, sizes: list[int]) -> list[bytes]:  # type: ignore[no-untyped-def]
    """Alternate messages like the protocol does: a -> b, b -> a (reversed)."""
    session = p.a.open(2)

    async def bob() -> None:
        peer, sess = await p.b.accept()
        for _ in sizes:
            data = await p.b.receive(peer, sess)
            await p.b.send(peer, sess, data[::-1])

    task = asyncio.create_task(bob())
    replies = []
    messages = [os.urandom(n) for n in sizes]
    for message in messages:
        await p.a.send(2, session, message)
        replies.append(await p.a.receive(2, session))
    await task
    assert replies == [m[::-1] for m in messages]
    return replies


@pytest.mark.parametrize("name", list(PROFILES))
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_messages_survive_loss_corruption_duplication_and_reordering(name: str, seed: int) -> None:
    async def main() -> None:
        async with pair(PROFILES[name], HARSH, seed) as p:
            await _echo(p, [1, 150, 3000, 20_000])
            dropped = {**p.a.stats.dropped}
            for k, v in p.b.stats.dropped.items():
                dropped[k] = dropped.get(k, 0) + v
            assert p.channel.stats.lost > 0 and p.channel.stats.corrupted > 0
            assert sum(dropped.values()) > 0  # corrupted frames were counted, not delivered

    run_simulated(main())


@pytest.mark.parametrize("name", ["eu868-sf7", "eu868-sf12"])
def test_the_duty_cycle_budget_is_never_exceeded(name: str) -> None:
    async def main() -> float:
        async with pair(PROFILES[name], Impairments(loss=0.1), 5) as p:
            loop = asyncio.get_running_loop()
            await _echo(p, [30_000 if name == "eu868-sf7" else 3_000])
            for log in p.logs.values():
                for start, _, _ in log:
                    window = sum(a for s, a, _ in log if start <= s < start + 3600 - 1e-6)
                    assert window <= 36.0 + 1e-6
            total = sum(a for log in p.logs.values() for _, a, _ in log)
            assert total > 36.0  # the run needed more than one hour's budget ...
            return loop.time()

    assert run_simulated(main()) > 3600.0  # ... so it waited, in virtual time


def test_the_endpoint_tells_how_long_a_queued_frame_waits_for_the_budget() -> None:
    """What the fail-safe's watch reads while a run is under way: nothing before the budget
    runs out, then the wait until the hour's first transmissions leave the window."""

    async def main() -> list[float]:
        async with pair(PROFILES["eu868-sf7"], seed=5) as p:
            waits = [p.a.budget_wait()]
            session = p.a.open(2)
            sending = asyncio.create_task(p.a.send(2, session, os.urandom(30_000)))
            while max(waits) == 0.0 and not sending.done():
                await p.a.clock.sleep(1.0)
                waits.append(p.a.budget_wait())
            sending.cancel()
            return waits

    waits = run_simulated(main())
    assert waits[0] == 0.0 and 3000.0 < waits[-1] < 3600.0
    assert 30.0 < len(waits) < 60.0  # the 32.4 s of data airtime an hour allows, sent first


def test_us915_frames_respect_the_dwell_time() -> None:
    async def main() -> None:
        async with pair(PROFILES["us915-sf9"]) as p:
            await _echo(p, [5000])
            assert all(a <= 0.400 for log in p.logs.values() for _, a, _ in log)
            assert max(n for log in p.logs.values() for _, _, n in log) == 66

    run_simulated(main())


def test_frames_at_10_percent_loss_stay_within_1_3x_of_a_clean_run() -> None:
    sizes = [120, 2900, 520, 3600, 9100, 1100, 700, 200]  # a paper-pair run's messages

    async def frames(loss: float, seed: int) -> int:
        async with pair(PROFILES["eu868-sf7"], Impairments(loss=loss), seed) as p:
            await _echo(p, sizes)
            return p.a.stats.frames_sent + p.b.stats.frames_sent

    clean = run_simulated(frames(0.0, 0))
    lossy = sorted(run_simulated(frames(0.1, seed)) for seed in range(15))
    assert lossy[len(lossy) // 2] <= 1.3 * clean


def test_a_vanished_peer_gives_a_timeout_not_a_hang() -> None:
    async def main() -> float:
        async with pair(PROFILES["us915-sf7"]) as p:
            loop = asyncio.get_running_loop()
            session = p.a.open(2)
            await p.b.close()  # Bob's radio is gone
            with pytest.raises(LinkTimeout, match="silent after"):
                await p.a.send(2, session, os.urandom(2000))
            return loop.time()

    assert run_simulated(main()) < 600.0


def test_a_peer_no_longer_heard_ends_the_wait_long_before_the_idle_timeout() -> None:
    """A run waits for a drone that flew out of range or landed: told how to know (``gone``:
    its beacons stopped), the link gives up once the session too has been quiet for
    GONE_QUIET_S, not after the idle timeout (5 minutes on US915); a peer still heard is
    waited for as long as before."""

    async def main(heard: bool) -> float:
        async with pair(PROFILES["us915-sf7"]) as p:
            session = p.a.open(2)
            start = p.a.clock.now()
            with pytest.raises(LinkTimeout):
                await p.a.receive(2, session, gone=lambda: not heard)
            return p.a.clock.now() - start

    idle = LinkConfig().idle_timeout(PROFILES["us915-sf7"])
    assert GONE_QUIET_S <= run_simulated(main(False)) <= GONE_QUIET_S + GONE_CHECK_S + 0.1
    assert run_simulated(main(True)) >= idle


def test_silence_while_waiting_for_a_message_times_out() -> None:
    async def main() -> None:
        cfg = LinkConfig(idle_timeout_s=30.0)
        async with pair(PROFILES["ideal"], config=cfg) as p:
            session = p.a.open(2)
            with pytest.raises(LinkTimeout, match="nothing from node 2"):
                await p.a.receive(2, session)

    run_simulated(main())


def test_abort_reaches_the_peer_and_frees_the_session() -> None:
    async def main() -> None:
        async with pair(PROFILES["eu868-sf9"]) as p:
            session = p.a.open(2)
            await p.a.send(2, session, b"hello")
            peer, sess = await p.b.accept()
            assert await p.b.receive(peer, sess) == b"hello"
            p.b.abort(peer, sess, AbortCode.PROTOCOL)
            with pytest.raises(PeerAborted, match="protocol") as info:
                await p.a.receive(2, session)
            assert info.value.code is AbortCode.PROTOCOL
            assert p.a.receiver.pending() == 0 and p.b.receiver.pending() == 0

    run_simulated(main())


def test_oversized_messages_are_refused_before_sending() -> None:
    async def main() -> None:
        async with pair(PROFILES["ideal"], config=LinkConfig(max_message=1000)) as p:
            session = p.a.open(2)
            with pytest.raises(MessageTooLarge):
                await p.a.send(2, session, bytes(1001))
            assert p.a.stats.frames_sent == 0

    run_simulated(main())


def test_garbage_on_the_air_is_counted_and_ignored() -> None:
    async def main() -> None:
        async with pair(PROFILES["ideal"]) as p:
            for n in range(300):  # put on the air by a's radio, beside its endpoint
                await p.a.transport.transmit(os.urandom(1 + n % 259), 0.01)
            await p.a.clock.sleep(1.0)  # the last one lands
            assert sum(p.b.stats.dropped.values()) == 300
            await _echo(p, [500])  # and the endpoint still works

    run_simulated(main())


def test_a_simulation_in_which_everything_waits_forever_raises() -> None:
    async def main() -> None:
        await asyncio.Event().wait()

    with pytest.raises(SimulationStalled):
        run_simulated(main())


def test_sending_on_a_closed_endpoint_fails_cleanly() -> None:
    async def main() -> None:
        async with pair(PROFILES["ideal"]) as p:
            session = p.a.open(2)
            await p.a.close()
            with pytest.raises(LinkError, match="not running"):
                await p.a.send(2, session, b"late")
            p.a.abort(
                2, session, AbortCode.SHUTDOWN
            )  # an abort after close only forgets the session
            assert not p.a.open_sessions

    run_simulated(main())


def test_sessions_opened_by_peers_are_bounded() -> None:
    async def main() -> None:
        async with pair(PROFILES["ideal"], config=LinkConfig(max_sessions=3)) as p:
            for _ in range(5):
                await p.a.send(2, p.a.open(2), b"hi")
            assert p.b.open_sessions == 3
            assert p.b.stats.dropped["too_many_sessions"] == 2

    run_simulated(main())


@pytest.mark.parametrize("carrier_sense", [False, True])
def test_three_nodes_share_one_channel_with_collisions(carrier_sense: bool) -> None:
    """Two senders talk to one receiver at once: without listen-before-talk their frames
    collide and ARQ sorts it out; with it, they take turns and collisions all but vanish."""

    async def main() -> None:
        clock = Clock()
        channel = Channel(Impairments(loss=0.05), seed=4, carrier_sense=carrier_sense)
        medium = SimMedium(channel, clock)
        link = PROFILES["us915-sf7"]
        nodes = [LinkEndpoint(n, medium.attach(n), link, clock=clock) for n in (1, 2, 3)]
        for node in nodes:
            await node.start()
        hub = nodes[1]
        payloads = {1: os.urandom(4000), 3: os.urandom(3000)}

        async def sender(node: LinkEndpoint) -> None:
            await node.send(2, node.open(2, session=node.node), payloads[node.node])

        async def receiver() -> dict[int, bytes]:
            got = {}
            for _ in range(2):
                peer, session = await hub.accept()
                got[peer] = await hub.receive(peer, session)
            return got

        task = asyncio.create_task(receiver())
        await asyncio.gather(sender(nodes[0]), sender(nodes[2]))
        assert await task == payloads
        if carrier_sense:
            assert channel.stats.collisions <= 2  # only frames started at the same instant
        else:
            assert channel.stats.collisions > 0
        for node in nodes:
            await node.close()

    run_simulated(main())


def test_an_aborted_session_answers_late_requests_with_abort() -> None:
    """Even if every ABORT copy is lost, the peer's next ACK request is answered by one."""

    async def main() -> None:
        async with pair(PROFILES["ideal"]) as p:
            session = p.a.open(2)
            await p.a.send(2, session, b"hello")
            peer, sess = await p.b.accept()
            real, lost = p.b.transport.transmit, list[bytes]()

            async def lose_aborts(frame: bytes, airtime: float) -> None:
                if decode_frame(frame).type is FrameType.ABORT and len(lost) < 3:
                    lost.append(frame)  # the three copies never make it to the air
                    return
                await real(frame, airtime)

            p.b.transport.transmit = lose_aborts  # type: ignore[method-assign]
            p.b.abort(peer, sess, AbortCode.PROTOCOL)
            with pytest.raises(PeerAborted, match="protocol"):
                await p.a.send(2, session, b"more")
            assert len(lost) == 3

    run_simulated(main())


class Blackout:
    """A transport that does not hear the frames ``lost(frame, now)`` picks."""

    def __init__(self, inner: SimTransport, lost: Callable[[bytes, float], bool]) -> None:
        self.inner, self.lost = inner, lost

    def set_receiver(self, callback: Callable[[bytes], None]) -> None:
        clock = self.inner.medium.clock

        def hear(frame: bytes) -> None:
            if not self.lost(frame, clock.now()):
                callback(frame)

        self.inner.set_receiver(hear)

    async def transmit(self, frame: bytes, airtime: float) -> None:
        await self.inner.transmit(frame, airtime)

    async def close(self) -> None:
        await self.inner.close()


def test_a_message_is_not_delivered_twice_when_its_ack_is_lost_past_the_idle_timeout() -> None:
    """The interleaving behind "expected message type GATES, got 4" at 30 % loss.

    b sends a one-fragment message; a delivers it, but every COMPLETE acknowledgement and every
    probe of that message is lost for longer than the link's idle timeout, while a sends a
    reply and b acknowledges it (the session is busy all along).  a must still recognise the
    message when b's probe finally gets through: answer COMPLETE, not start a new copy (a new
    epoch would make b send it all again and a deliver it a second time)."""
    idle = 20.0
    window: list[float] = []  # [start, end] of the blackout, once the message was delivered

    def blacked_out(frame: bytes, now: float) -> bool:
        head = decode_frame(frame)
        if not window or not window[0] <= now < window[1] or head.seq != 0:
            return False
        # b's copies and probes of its message 0, and a's acknowledgements of it
        return (head.src, head.type) in ((2, FrameType.DATA), (1, FrameType.ACK))

    async def main() -> None:
        clock = Clock()
        medium = SimMedium(Channel(seed=1), clock)
        config = LinkConfig(idle_timeout_s=idle)
        a = LinkEndpoint(
            1, Blackout(medium.attach(1), blacked_out), PROFILES["us915-sf7"], config, clock
        )
        b = LinkEndpoint(
            2, Blackout(medium.attach(2), blacked_out), PROFILES["us915-sf7"], config, clock
        )
        async with a, b:
            session = a.open(2)

            async def bob() -> None:
                peer, sess = await b.accept()
                assert await b.receive(peer, sess) == b"ping"
                await b.send(peer, sess, b"pong")  # returns once a's COMPLETE gets through
                assert await b.receive(peer, sess, idle_timeout=600) == bytes(8000)
                await b.send(peer, sess, b"done")

            task = asyncio.create_task(bob())
            await a.send(2, session, b"ping")
            assert await a.receive(2, session) == b"pong"
            window[:] = [clock.now(), clock.now() + 3 * idle]
            await a.send(2, session, bytes(8000))  # 39 fragments, some 14 s on the air
            assert await a.receive(2, session, idle_timeout=600) == b"done"
            await task
            assert a.stats.messages_received == 2
            assert clock.now() > window[1]  # the blackout outlasted the idle timeout

    run_simulated(main())


def test_a_dying_link_task_is_logged_and_fails_every_waiter(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The transmit task dies (the radio raised): it is logged at once with its traceback and
    as a task_failed event, and a pending send, a receive and an accept get a LinkError
    instead of waiting for a timeout (or forever); closing afterwards is clean."""

    async def main() -> None:
        async with pair(PROFILES["us915-sf7"]) as p:
            sent = 0

            async def transmit(frame: bytes, airtime: float) -> None:
                nonlocal sent
                sent += 1
                if sent > 2:
                    raise OSError(5, "Input/output error")  # the modem was unplugged
                await p.a.clock.sleep(airtime)

            p.a.transport.transmit = transmit  # type: ignore[method-assign]
            session = p.a.open(2)
            receiving = asyncio.create_task(p.a.receive(2, session))
            accepting = asyncio.create_task(p.a.accept())
            with pytest.raises(LinkError, match="the link failed: OSError"):
                await p.a.send(2, session, os.urandom(5000))  # more than two frames
            for waiter in (receiving, accepting):
                with pytest.raises(LinkError, match="the link failed"):
                    await waiter
            with pytest.raises(LinkError, match="the link failed"):
                await p.a.send(2, p.a.open(2), b"later")

    with caplog.at_level(logging.ERROR, logger="companion.radio"):
        run_simulated(main())
    (record,) = [r for r in caplog.records if getattr(r, "event", None) == "task_failed"]
    assert record.getMessage().startswith("task link-1-tx failed: OSError")
    assert record.exc_info is not None and record.exc_info[0] is OSError  # the traceback
    assert record.fields["task"] == "link-1-tx"  # type: ignore[attr-defined]


async def _three_nodes(clock: Clock) -> tuple[LinkEndpoint, LinkEndpoint, LinkEndpoint]:
    """Nodes 1, 2 and 3 started on one lossless US915 SF7 channel."""
    medium = SimMedium(Channel(Impairments(), seed=5), clock)
    link = PROFILES["us915-sf7"]
    a, b, c = (LinkEndpoint(n, medium.attach(n), link, clock=clock) for n in (1, 2, 3))
    for node in (a, b, c):
        await node.start()
    return a, b, c


def test_a_third_node_hears_who_is_in_a_run_and_when_the_channel_fell_quiet() -> None:
    """Frame headers are public: a node that overhears another pair's session knows both are
    engaged (a request to either would be refused BUSY) until ENGAGED_CYCLES frame-ACK cycles of
    silence, and how long other pairs' runs have left the channel quiet; its own sessions
    count for neither."""

    async def main() -> None:
        clock = Clock()
        a, b, c = await _three_nodes(clock)
        assert not c.engaged(1) and not c.engaged(2)
        assert c.others_quiet_s() == float("inf")

        async def answer() -> None:
            peer, session = await b.accept()
            await b.receive(peer, session)

        task = asyncio.create_task(answer())
        await a.send(2, a.open(2), os.urandom(2000))
        await task
        assert c.engaged(1) and c.engaged(2) and not c.engaged(3)
        assert c.others_quiet_s() < c.cycle_s
        # the pair's own view: neither counts its own session as another pair's
        assert not a.engaged(2) and not b.engaged(1)
        assert a.others_quiet_s() == float("inf")
        await clock.sleep(ENGAGED_CYCLES * c.cycle_s + 0.01)
        assert not c.engaged(1) and not c.engaged(2)
        assert c.others_quiet_s() > ENGAGED_CYCLES * c.cycle_s
        for node in (a, b, c):
            await node.close()

    run_simulated(main())


def test_the_channel_load_counts_every_frame_heard_and_sent() -> None:
    """A node's view of how loaded the channel is (what the companion waits on before it
    starts a run): the share of the last seconds carrying frames it heard -- another pair's
    run, beacons -- or sent itself, back to nothing once the channel is quiet."""

    async def main() -> None:
        clock = Clock()
        a, b, c = await _three_nodes(clock)
        assert c.load(5.0) == 0.0

        async def answer() -> None:
            peer, session = await b.accept()
            await b.receive(peer, session)

        task = asyncio.create_task(answer())
        began = clock.now()
        await a.send(2, a.open(2), os.urandom(4000))
        await task
        took = clock.now() - began
        # 4000 B is 20 full frames: the channel carried them most of the time
        assert took > 5.0
        for node in (a, b, c):
            assert 0.6 < node.load(5.0) <= 1.0
        # the sender counts its own frames as the third node hears them
        assert abs(a.load(took) - c.load(took)) < 0.05
        await clock.sleep(5.01)
        assert c.load(5.0) == 0.0 and a.load(5.0) == 0.0
        await c.beacon(b"x" * 20)
        await clock.sleep(1.0)  # (on the air, and heard)
        assert 0.0 < c.load(5.0) < 0.02 and 0.0 < a.load(5.0) < 0.02
        for node in (a, b, c):
            await node.close()

    run_simulated(main())


def test_beacons_get_on_the_air_between_a_runs_messages() -> None:
    """Two drones in a run send their messages one after the other, 10 ms apart frame by
    frame; a third drone's beacons must still get on the air.  A burst starts only on a
    channel idle for a moment (``LEAD_IDLE_S``), and a beacon looks at a busy channel more
    often than data does, so it takes that moment.  Before, a beacon found the channel busy
    until listen-before-talk gave up after 8 s and it went out into somebody's frame
    (busy_ten: 8 % of beacons)."""

    async def main() -> tuple[list[float], int]:
        clock = Clock()
        medium = SimMedium(Channel(Impairments(), seed=5), clock)
        a, b, c = (
            LinkEndpoint(n, medium.attach(n), PROFILES["us915-sf7"], clock=clock) for n in (1, 2, 3)
        )
        for node in (a, b, c):
            await node.start()

        async def run() -> None:
            session = a.open(2)
            for _ in range(12):
                await a.send(2, session, os.urandom(1500))  # seven frames, about 2.5 s
                await a.receive(2, session)

        async def bob() -> None:
            peer, session = await b.accept()
            for _ in range(12):
                await b.receive(peer, session)
                await b.send(peer, session, os.urandom(300))

        async def beacons() -> list[float]:
            await clock.sleep(2.0)
            waits = []
            for k in range(8):
                start = clock.now()
                await c.beacon(bytes([k]) * 40)
                waits.append(clock.now() - start)
                await clock.sleep(1.0)
            return waits

        waits = (await asyncio.gather(run(), bob(), beacons()))[2]
        heard = 0
        while not a.beacons.empty():
            heard += a.beacons.get_nowait()[0] == 3
        for node in (a, b, c):
            await node.close()
        return waits, heard

    waits, heard = run_simulated(main())
    assert max(waits) < 4.0, waits  # at most one message's burst (before: up to 8 s)
    assert heard == 8  # and none went out into a frame of the run
