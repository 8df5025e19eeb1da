"""Stress: many conversations over a bad channel, each message delivered once and in order.

Two endpoints on one simulated channel (virtual time) hold ping-pong sessions like the
protocol's: one side sends a turn of one or two messages, the other receives them, "computes"
for a random time and answers.  Sizes run from a few bytes to many fragments; compute delays
from nothing to several retransmission timeouts, which moves the replies across the sender's
retransmissions, polls and backoff.  Every message names itself (a type byte, conversation,
turn, index, length) and each side checks it receives exactly the other's messages, in order,
exactly once.  Independent of the protocol package.

The link's idle timeout (how long it keeps state about a silent peer) is cut to seconds, while
the parties wait minutes for an answer: that scales down what the default idle timeout (5 min)
does to the protocol's long messages, e.g. a reply that takes longer to send than the idle
timeout while the acknowledgement of the message it answers is still outstanding.
"""

from __future__ import annotations

import asyncio
import hashlib
import random
import struct
from dataclasses import dataclass

import pytest

from companion.radio import PROFILES, Clock, LinkConfig, LinkEndpoint, LinkProfile
from companion.radio import endpoint as endpoint_module
from companion.radio import reassembly as reassembly_module
from companion.sim.medium import Channel, Impairments, SimMedium
from companion.sim.virtual_time import run_simulated

HEADER = struct.Struct(">BHHHI")  # type, conversation, turn, index in the turn, body length
A_NODE, B_NODE = 1, 2


@dataclass(frozen=True)
class Turn:
    sender: int  # A_NODE or B_NODE
    sizes: tuple[int, ...]  # body sizes of the turn's messages
    delay: float  # the receiver "computes" this long before the next turn


def message(conversation: int, turn: int, index: int, sender: int, size: int) -> bytes:
    """A message that names itself; the type byte differs between consecutive messages."""
    kind = 0x10 + 4 * (turn % 8) + 2 * (sender == B_NODE) + index
    head = HEADER.pack(kind, conversation, turn, index, size)
    body, block = bytearray(), head
    while len(body) < size:
        block = hashlib.sha256(block).digest()
        body += block
    return head + bytes(body[:size])


def describe(data: bytes) -> str:
    if len(data) < HEADER.size:
        return f"{len(data)} bytes"
    kind, conversation, turn, index, size = HEADER.unpack_from(data)
    return f"type {kind:#x} (conversation {conversation} turn {turn}.{index}, {size} B)"


def script(
    rng: random.Random, turns: int, rto: float, max_size: int, min_large: int = 600
) -> list[Turn]:
    out = []
    for number in range(turns):
        count = 1 if rng.random() < 0.8 else 2
        sizes = tuple(
            rng.choice([rng.randint(0, 40), rng.randint(41, 600), rng.randint(min_large, max_size)])
            for _ in range(count)
        )
        delay = rng.choice([0.0, rng.uniform(0.0, rto), rng.uniform(rto, 6 * rto)])
        out.append(Turn(A_NODE if number % 2 == 0 else B_NODE, sizes, delay))
    return out


def expected(conversation: int, turns: list[Turn], sender: int) -> list[bytes]:
    return [
        message(conversation, number, index, turn.sender, size)
        for number, turn in enumerate(turns)
        if turn.sender == sender
        for index, size in enumerate(turn.sizes)
    ]


class Conversations:
    """Runs scripted conversations between ``a`` (opens) and ``b`` (accepts)."""

    def __init__(self, a: LinkEndpoint, b: LinkEndpoint, receive_timeout: float) -> None:
        self.a, self.b = a, b
        self.receive_timeout = receive_timeout  # how long a party waits for an answer
        self.received: dict[tuple[int, int], list[bytes]] = {}
        self._incoming: dict[int, asyncio.Future[tuple[int, bytes]]] = {}

    async def dispatch(self) -> None:
        """b's accept loop: route each new session to its conversation by its first message."""
        while True:
            peer, session = await self.b.accept()
            first = await self.b.receive(peer, session, idle_timeout=self.receive_timeout)
            conversation = HEADER.unpack_from(first)[1]
            self._incoming[conversation].set_result((session, first))

    async def run(self, conversation: int, turns: list[Turn]) -> None:
        loop = asyncio.get_running_loop()
        self._incoming[conversation] = loop.create_future()
        session = self.a.open(B_NODE)
        await asyncio.gather(
            self._side(self.a, B_NODE, session, conversation, turns),
            self._side(self.b, A_NODE, None, conversation, turns),
        )
        b_session, _ = self._incoming.pop(conversation).result()
        self.a.close_session(B_NODE, session)
        self.b.close_session(A_NODE, b_session)
        for node, peer in ((A_NODE, B_NODE), (B_NODE, A_NODE)):
            assert self.received[(conversation, node)] == expected(conversation, turns, peer)

    async def _side(
        self,
        me: LinkEndpoint,
        peer: int,
        session: int | None,
        conversation: int,
        turns: list[Turn],
    ) -> None:
        got_list = self.received.setdefault((conversation, me.node), [])
        for number, turn in enumerate(turns):
            messages = [
                message(conversation, number, index, turn.sender, size)
                for index, size in enumerate(turn.sizes)
            ]
            if turn.sender == me.node:
                assert session is not None
                for data in messages:
                    await me.send(peer, session, data)
                continue
            for want in messages:
                if session is None:
                    session, got = await self._incoming[conversation]
                else:
                    got = await me.receive(peer, session, idle_timeout=self.receive_timeout)
                got_list.append(got)
                assert got == want, f"node {me.node} expected {describe(want)}, got {describe(got)}"
            await me.clock.sleep(turn.delay)  # compute the answer


async def stress(
    link: LinkProfile,
    impairments: Impairments,
    seed: int,
    *,
    conversations: int,
    turns: int,
    max_size: int,
    idle_timeout_s: float | None,
    parallel: int = 1,
    receive_timeout: float = 600.0,
    min_large: int = 600,
) -> tuple[LinkEndpoint, LinkEndpoint]:
    rng = random.Random(seed)
    clock = Clock()
    medium = SimMedium(Channel(impairments, seed), clock)
    config = LinkConfig(idle_timeout_s=idle_timeout_s)
    a = LinkEndpoint(A_NODE, medium.attach(A_NODE), link, config, clock)
    b = LinkEndpoint(B_NODE, medium.attach(B_NODE), link, config, clock)
    rto = a.retransmission_floor(B_NODE)
    async with a, b:
        runner = Conversations(a, b, receive_timeout)
        dispatcher = asyncio.create_task(runner.dispatch())
        try:
            for start in range(0, conversations, parallel):
                batch = range(start, min(start + parallel, conversations))
                await asyncio.gather(
                    *(runner.run(c, script(rng, turns, rto, max_size, min_large)) for c in batch)
                )
        finally:
            dispatcher.cancel()
        assert a.receiver.pending() == 0 and b.receiver.pending() == 0
        assert not a.open_sessions and not b.open_sessions
    return a, b


VARIANTS = {
    "loss": Impairments(loss=0.3),
    "loss+reorder": Impairments(loss=0.3, reorder=0.2, reorder_delay_s=2.0),
    "loss+duplicate": Impairments(loss=0.3, duplicate=0.2, reorder_delay_s=2.0),
    "loss+corrupt": Impairments(loss=0.3, corrupt=0.1),
    "everything": Impairments(loss=0.3, corrupt=0.05, duplicate=0.1, reorder=0.1),
}


class SeededSecrets:
    """Stands in for ``secrets`` (session ids, epochs) so that a failure repeats."""

    def __init__(self, seed: int) -> None:
        self._rng = random.Random(seed)

    def randbelow(self, n: int) -> int:
        return self._rng.randrange(n)


@pytest.fixture(autouse=True)
def _seeded(monkeypatch: pytest.MonkeyPatch) -> None:
    """The link's own random choices (probe jitter, session ids, epochs) come from the OS;
    seed them too, so that a run is a function of the test's parameters."""
    monkeypatch.setattr(endpoint_module, "_JITTER", random.Random(12345))
    monkeypatch.setattr(endpoint_module, "secrets", SeededSecrets(1))
    monkeypatch.setattr(reassembly_module, "secrets", SeededSecrets(2))


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("seed", [1, 2])
def test_ping_pong_sessions_deliver_every_message_once_in_order(variant: str, seed: int) -> None:
    run_simulated(
        stress(
            PROFILES["us915-sf7"],
            VARIANTS[variant],
            seed,
            conversations=6,
            turns=8,
            max_size=6000,
            idle_timeout_s=8.0,
        )
    )


@pytest.mark.parametrize(
    ("name", "idle", "max_size", "wait"),
    [
        ("us915-sf9", 8.0, 3000, 600.0),
        ("ideal", 2.0, 20_000, 600.0),
        ("eu868-sf7", 60.0, 3000, 4 * 3600.0),  # a peer out of budget is silent for an hour
    ],
)
def test_other_profiles(name: str, idle: float, max_size: int, wait: float) -> None:
    """Small frames (many fragments per message), a fast radio, a duty-cycled one."""
    run_simulated(
        stress(
            PROFILES[name],
            VARIANTS["everything"],
            3,
            conversations=4,
            turns=8,
            max_size=max_size,
            idle_timeout_s=idle,
            receive_timeout=wait,
        )
    )


def test_concurrent_sessions_share_the_radio() -> None:
    """Three conversations at once between the same two radios.  (Known limit, not checked
    here: with several sessions a node sends the next session's data right after a POLL or
    ACK request, so it can be on the air when the answer comes; a couple of runs in a hundred
    of this shape end in LinkTimeout after 20 unanswered probes.  Never in wrong data.)"""
    run_simulated(
        stress(
            PROFILES["us915-sf7"],
            VARIANTS["everything"],
            4,
            conversations=6,
            turns=8,
            max_size=4000,
            idle_timeout_s=30.0,
            parallel=3,
        )
    )


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(20, 30))
def test_protocol_sized_messages_with_the_default_idle_timeout(seed: int) -> None:
    """The reported case unscaled: the default idle timeout (5 min on US915), 30 % loss and
    mostly messages of 80-150 kB, as long as the protocol's TESTS, whose transfer can outlast
    the idle timeout while the acknowledgement of the message before is still outstanding
    (the receiver that forgot it after 5 min delivered that message twice in half the seeds)."""
    run_simulated(
        stress(
            PROFILES["us915-sf7"],
            Impairments(loss=0.3),
            seed,
            conversations=3,
            turns=8,
            max_size=150_000,
            min_large=80_000,
            idle_timeout_s=None,
        )
    )
