"""Beacons (signed, tagged, certificates) and what a companion makes of them (neighbours)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.auth.beacon_keys import BeaconKeys
from companion.auth.certificate import Certificate
from companion.auth.keys import SigningKey
from companion.auth.trust import Operator, TrustStore
from companion.mission.levels import Slots
from companion.neighbours.beacon import (
    BODY_SIZE,
    CERT_BEACON_SIZE,
    MAX_TAGS,
    SIGNED_SIZE,
    TAG_SIZE,
    Beacon,
    BeaconError,
    CertBeacon,
    SignedBeacon,
    TaggedBeacon,
    decode_beacon,
    keys_hash,
    size_class,
)
from companion.neighbours.registry import NO_TAG, UNHEARD, Heard, Neighbours
from companion.state import StateStore
from protocol.messages import Suite

NOW = int(time.time())


SLOTS = Slots(303, 0b110)  # 510-520 m AMSL


def beacon(t: int = NOW, counter: int = 0, slots: Slots = SLOTS) -> Beacon:
    return Beacon(
        473_977_420, 85_455_940, 518, False, frozenset({Suite.COMPACT}), 7, t, counter, slots, 3
    )


class Drone:
    def __init__(self, node: int, operator: SigningKey, store: Path) -> None:
        self.node, self.key, self.keys = node, SigningKey.generate(), BeaconKeys()
        self.cert = Certificate.issue(operator, self.key.public, node, NOW - 60, NOW + 3600)
        self.keys_hash = keys_hash(b"b" * 16, self.keys.public, b"")
        trust = TrustStore([Operator("acme", operator.public)])
        self.neighbours = Neighbours(trust, StateStore(store / f"n{node}"), self.cert, self.keys)

    def signed(self, b: Beacon, *, tag_for: list[bytes] | None = None) -> bytes:
        return b.signed(self.node, self.key, self.keys.public, self.keys_hash, tag_for or [])

    def tagged(self, b: Beacon) -> bytes:
        return b.tagged(self.node, self.neighbours.tag_keys(0))

    def cert_beacon(self, want: bool = False) -> bytes:
        return CertBeacon(self.cert, want).encode()


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Drone, Drone]:
    acme = SigningKey.generate()
    return Drone(1, acme, tmp_path), Drone(2, acme, tmp_path)


def test_formats_and_sizes(pair: tuple[Drone, Drone]) -> None:
    a, _ = pair
    signed = a.signed(beacon())
    assert len(signed) == SIGNED_SIZE == 138 and BODY_SIZE == 26
    decoded = decode_beacon(signed)
    assert isinstance(decoded, SignedBeacon) and decoded.beacon == beacon(t=NOW)
    assert decoded.signed_by(1, a.key.public) and not decoded.signed_by(2, a.key.public)
    tagged = beacon().tagged(1, [b"k" * 32, b"l" * 32])
    assert len(tagged) == 26 + 2 * 4
    assert isinstance(decode_beacon(tagged), TaggedBeacon)
    assert len(a.cert_beacon()) == CERT_BEACON_SIZE == 117
    assert size_class(1) == 0 and size_class(4) == 2 and size_class(5) == 3


@settings(max_examples=400)
@given(st.binary(max_size=260))
def test_decoder_fuzz(data: bytes) -> None:
    try:
        decode_beacon(data)
    except BeaconError:
        pass


def test_two_drones_meet_and_check_each_other(pair: tuple[Drone, Drone]) -> None:
    a, b = pair
    # B hears A's signed beacon before A's certificate: kept, checked once it comes
    assert b.neighbours.hear(1, a.signed(beacon()), NOW).kind is Heard.UNKNOWN
    cert = b.neighbours.hear(1, a.cert_beacon(), NOW)
    assert cert.kind is Heard.CERTIFICATE and cert.then is not None
    assert cert.then.kind is Heard.POSITION and cert.then.new_keys
    a.neighbours.hear(2, b.cert_beacon(), NOW)
    got = a.neighbours.hear(2, b.signed(beacon(counter=1)), NOW)
    assert got.kind is Heard.POSITION and got.neighbour is not None and not got.neighbour.knows_us
    # now each holds the other's beacon key: tagged beacons check, and say "I know you"
    got = a.neighbours.hear(2, b.tagged(beacon(counter=2)), NOW)
    assert got.kind is Heard.POSITION and got.neighbour is not None and got.neighbour.knows_us
    assert b.neighbours.hear(1, a.tagged(beacon(counter=3)), NOW + 1).kind is Heard.POSITION


def test_a_neighbour_that_tagged_us_before_has_only_not_heard_us_lately(
    pair: tuple[Drone, Drone], tmp_path: Path
) -> None:
    """A's beacon without a tag for B after one with it: A has B's key but has not heard B
    within its silence period (UNHEARD: a tagged beacon of B's will do) -- once; a second
    such beacon, or one from a drone that never tagged for B, asks for a signed one."""
    a, b = pair
    a.neighbours.hear(2, b.cert_beacon(), NOW)
    a.neighbours.hear(2, b.signed(beacon()), NOW)
    b.neighbours.hear(1, a.cert_beacon(), NOW)
    assert b.neighbours.hear(1, a.signed(beacon()), NOW).kind is Heard.POSITION
    assert b.neighbours.hear(1, a.tagged(beacon(counter=1)), NOW).kind is Heard.POSITION
    untagged = beacon(counter=2).tagged(1, [])  # A heard nobody lately: no tags
    assert b.neighbours.hear(1, untagged, NOW).reason == UNHEARD
    assert b.neighbours.hear(1, beacon(counter=3).tagged(1, []), NOW).reason == NO_TAG
    assert b.neighbours.hear(1, a.tagged(beacon(counter=4)), NOW).kind is Heard.POSITION
    assert b.neighbours.hear(1, beacon(counter=5).tagged(1, []), NOW).reason == UNHEARD
    # to a B that never had a tag from A (a fresh start), A lacks B's key: a signed beacon
    # of B's is needed
    again = Neighbours(b.neighbours.trust, StateStore(tmp_path / "again"), b.cert, b.keys)
    again.hear(1, a.cert_beacon(), NOW)
    assert again.hear(1, a.signed(beacon(counter=6)), NOW).kind is Heard.POSITION
    assert again.hear(1, beacon(counter=7).tagged(1, []), NOW).reason == NO_TAG


def test_every_neighbour_of_a_busy_sky_checks_our_tagged_beacon(tmp_path: Path) -> None:
    """Ten drones in range: each has nine neighbours.  With at most 8 tags a beacon left out
    the neighbour heard least lately, which could not check it (a lost position; it then
    asked for a signed beacon, 138 bytes): in busy_ten 24-30 signed beacons per drone.  Now
    a tagged beacon carries up to MAX_TAGS, and is still no larger than a signed one."""
    assert BODY_SIZE + TAG_SIZE * MAX_TAGS <= SIGNED_SIZE
    acme = SigningKey.generate()
    a = Drone(1, acme, tmp_path)
    others = [Drone(node, acme, tmp_path) for node in range(2, 11)]  # nine
    for counter, o in enumerate(others):
        a.neighbours.hear(o.node, o.cert_beacon(), NOW)
        assert a.neighbours.hear(o.node, o.signed(beacon()), NOW).kind is Heard.POSITION
        o.neighbours.hear(1, a.cert_beacon(), NOW)
        assert o.neighbours.hear(1, a.signed(beacon(counter=counter)), NOW).kind is Heard.POSITION
    tagged = a.tagged(beacon(counter=len(others)))
    assert len(tagged) == BODY_SIZE + TAG_SIZE * len(others)
    for o in others:
        got = o.neighbours.hear(1, tagged, NOW + 1)
        assert got.kind is Heard.POSITION and got.neighbour is not None
        assert got.neighbour.knows_us  # and it tells each that A heard it


def test_forged_stale_and_replayed_beacons_are_dropped(pair: tuple[Drone, Drone]) -> None:
    a, b = pair
    b.neighbours.hear(1, a.cert_beacon(), NOW)
    first = a.signed(beacon(counter=5))
    assert b.neighbours.hear(1, first, NOW).kind is Heard.POSITION
    assert b.neighbours.hear(1, first, NOW).reason.endswith("(a replay)")
    older = a.signed(beacon(counter=4))
    assert b.neighbours.hear(1, older, NOW).kind is Heard.REJECTED
    stale = a.signed(beacon(t=NOW - 120, counter=9))
    assert "off" in b.neighbours.hear(1, stale, NOW).reason
    mallory = SigningKey.generate()  # signs as node 1 with its own key
    forged = beacon(counter=20).signed(1, mallory, a.keys.public, a.keys_hash)
    assert b.neighbours.hear(1, forged, NOW).reason == "signature does not verify"
    # a tagged beacon with made-up tags: no tag for B, not used
    fake = beacon(counter=21).tagged(1, [b"x" * 32])
    assert b.neighbours.hear(1, fake, NOW).kind is Heard.UNKNOWN
    # the replay memory is on disk: a new Neighbours on the same store still refuses it
    again = Neighbours(b.neighbours.trust, b.neighbours.store, b.cert, b.keys)
    again.hear(1, a.cert_beacon(), NOW)
    assert again.hear(1, first, NOW).kind is Heard.REJECTED


def test_untrusted_and_squatting_drones(tmp_path: Path) -> None:
    acme = SigningKey.generate()
    a, b = Drone(1, acme, tmp_path), Drone(2, acme, tmp_path)
    rogue = Drone(1, SigningKey.generate(), tmp_path / "rogue")  # another operator, node 1
    heard = b.neighbours.hear(1, rogue.cert_beacon(), NOW)
    assert heard.kind is Heard.UNTRUSTED and heard.reason == "operator not in the trust store"
    assert b.neighbours.untrusted(1)
    untrusted = b.neighbours.hear(1, rogue.signed(beacon()), NOW)
    assert untrusted.kind is Heard.UNTRUSTED and untrusted.beacon is not None  # for alerts
    b.neighbours.hear(1, a.cert_beacon(), NOW)
    assert not b.neighbours.untrusted(1)
    # a drone of a trusted operator claiming node 1 while drone 1 is heard: refused
    squatter = Drone(1, acme, tmp_path / "squat")
    refused = b.neighbours.hear(1, squatter.cert_beacon(), NOW + 10)
    assert refused.kind is Heard.REJECTED and "in use" in refused.reason
    known = b.neighbours.get(1)
    assert known is not None and known.cert == a.cert
    # a certificate for another node id than the one it speaks from: refused
    wrong = Drone(3, acme, tmp_path / "wrong")
    assert (
        b.neighbours.hear(1, wrong.cert_beacon(), NOW).reason == "certificate names another node id"
    )


def test_beacon_keys_agree_per_direction() -> None:
    x, y = BeaconKeys(), BeaconKeys()
    xy = x.pair(b"X" * 8, b"Y" * 8, y.public)
    yx = y.pair(b"Y" * 8, b"X" * 8, x.public)
    assert xy is not None and yx is not None
    assert xy == (yx[1], yx[0]) and xy[0] != xy[1]
    assert x.pair(b"X" * 8, b"Y" * 8, bytes(32)) is None  # a low-order point
