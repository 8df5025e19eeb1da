"""The run's authenticated session: signed key exchange, AEAD on every message, refusals."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from companion.auth.session import (
    Accepted,
    AuthenticationError,
    Identity,
    Init,
    Initiator,
    Refusal,
    Refused,
    Responder,
    Route,
)
from companion.sim.fleet import make_fleet

NOW = time.time()
ROUTE = Route(1, 2, 4711)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Identity]:
    made = make_fleet([(1, "a"), (2, "b"), (3, "b")], Path(tmp_path_factory.mktemp("fleet")))
    return {node: c.identity for node, c in made.items()}


def handshake(
    fleet: dict[int, Identity], hello: bytes = b"HELLO", route: Route = ROUTE
) -> tuple[Initiator, Responder, bytes]:
    alice = Initiator(fleet[1], fleet[2].cert, route, NOW)
    msg1 = alice.first(hello)
    bob = Responder(fleet[2], Init.parse(msg1), route)
    bob.verify(fleet[1].cert, NOW, 30.0)
    return alice, bob, msg1


def test_a_whole_session(fleet: dict[int, Identity]) -> None:
    alice, bob, msg1 = handshake(fleet)
    assert bob.init.hello == b"HELLO" and len(msg1) == 109 + 5
    answer = alice.reply(bob.accept(b"B" * 16, b"OFFER", cover=5))
    assert answer == Accepted(b"B" * 16, 5, b"OFFER")
    for k in range(4):
        assert bob.open(alice.seal(b"from alice %d" % k)) == b"from alice %d" % k
        assert alice.open(bob.seal(b"from bob %d" % k)) == b"from bob %d" % k


def test_message_1_is_checked_before_any_work(fleet: dict[int, Identity]) -> None:
    alice = Initiator(fleet[1], fleet[2].cert, ROUTE, NOW)
    msg1 = alice.first(b"HELLO")
    for k in range(len(msg1)):  # every byte: signature, time, key, hello, fingerprint
        bad = bytearray(msg1)
        bad[k] ^= 0x40
        with pytest.raises(AuthenticationError):
            bob = Responder(fleet[2], Init.parse(bytes(bad)), ROUTE)
            bob.verify(fleet[1].cert, NOW, 30.0)
    bob = Responder(fleet[2], Init.parse(msg1), ROUTE)
    with pytest.raises(AuthenticationError, match="identity"):
        bob.verify(fleet[3].cert, NOW, 30.0)  # claims another drone's certificate
    with pytest.raises(AuthenticationError, match="before it arrived"):
        bob.verify(fleet[1].cert, NOW + 600, 30.0)  # a recording played ten minutes later
    # ... accepted with an hour's tolerance (no exception)
    Responder(fleet[2], Init.parse(msg1), ROUTE).verify(fleet[1].cert, NOW + 600, 30, 3600)
    for other in (Route(1, 2, 4712), Route(3, 2, 4711)):  # another session, another sender
        with pytest.raises(AuthenticationError):
            Responder(fleet[2], Init.parse(msg1), other).verify(fleet[1].cert, NOW, 30.0)
    with pytest.raises(AuthenticationError):  # meant for drone 2, not for drone 3
        Responder(fleet[3], Init.parse(msg1), ROUTE).verify(fleet[1].cert, NOW, 30.0)
    with pytest.raises(AuthenticationError):
        Init.parse(b"\x01short")


def test_forged_tampered_reordered_and_spliced_messages_fail(fleet: dict[int, Identity]) -> None:
    alice, bob, _ = handshake(fleet)
    reply = bob.accept(b"B" * 16, b"OFFER", cover=8)
    for k in range(len(reply)):
        bad = bytearray(reply)
        bad[k] ^= 0x01
        copy = Initiator.__new__(Initiator)
        copy.__dict__.update(alice.__dict__)
        with pytest.raises(AuthenticationError):
            copy.reply(bytes(bad))
    alice.reply(reply)
    first, second = alice.seal(b"one"), alice.seal(b"two")
    with pytest.raises(AuthenticationError):
        bob.open(second)  # reordered
    with pytest.raises(AuthenticationError):
        bob.open(first)  # a failed session stays failed
    # spliced: a message of another session between the same two drones
    alice2, bob2, _ = handshake(fleet, route=Route(1, 2, 99))
    alice2.reply(bob2.accept(b"C" * 16, b"OFFER", cover=8))
    alice3, bob3, _ = handshake(fleet)
    alice3.reply(bob3.accept(b"D" * 16, b"OFFER", cover=8))
    with pytest.raises(AuthenticationError):
        bob3.open(alice2.seal(b"spliced"))
    with pytest.raises(AuthenticationError):
        alice3.open(bob2.seal(b"spliced"))
    # a recorded answer replayed to a new request of the same drones
    alice4, _, _ = handshake(fleet)
    with pytest.raises(AuthenticationError):
        alice4.reply(reply)


def test_refusals_are_signed(fleet: dict[int, Identity]) -> None:
    alice, bob, _ = handshake(fleet)
    refusal = bob.refuse(Refusal.ROLE)
    assert alice.reply(refusal) == Refused(Refusal.ROLE)
    for k in range(len(refusal)):
        bad = bytearray(refusal)
        bad[k] ^= 0x01
        other, _, _ = handshake(fleet)
        with pytest.raises(AuthenticationError):
            other.reply(bytes(bad))
    # a stranger's (drone 3's) refusal of Alice's request to drone 2
    alice, _, msg1 = handshake(fleet)
    stranger = Responder(fleet[3], Init.parse(msg1), ROUTE)
    with pytest.raises(AuthenticationError, match="not signed by the peer"):
        alice.reply(stranger.refuse(Refusal.ROLE))
    with pytest.raises(AuthenticationError):
        stranger.accept(b"B" * 16, b"x", cover=8)  # never verified: never answered
