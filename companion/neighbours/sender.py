"""Our beacons out: a component that owns what it needs to send them.

Position beacons every interval (random phase and jitter; at once when asked: take-off, a new
peer, new altitude slots), tagged for every neighbour that holds our beacon key and signed now
and then (or when somebody lacks our key); certificate beacons at the start and when somebody
cannot check us yet.  :class:`Cadence` says how often each goes for a link profile -- the one
place those periods are worked out.  What a position beacon says comes from the companion
(:class:`OwnBeacon`); the sender stamps it (time and counter, always growing, also across
restarts) and signs or tags it.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import random
from collections.abc import Callable
from dataclasses import dataclass

from companion.auth.beacon_keys import BeaconKeys
from companion.auth.session import Identity
from companion.mission.levels import Slots
from companion.neighbours.beacon import Beacon, BeaconKind, CertBeacon, size_class
from companion.neighbours.beacon_airtime import beacon_interval
from companion.neighbours.peers import FRESH_S
from companion.neighbours.registry import Neighbours
from companion.radio.airtime import LinkProfile
from companion.radio.arq import LinkError
from companion.radio.endpoint import LinkEndpoint
from companion.state import OWN, StateStore
from protocol.messages import Suite

_JITTER = random.SystemRandom()
SIGNED_EVERY_S = 300.0  # a signed beacon at least this often (for drones that missed one),
SIGNED_EVERY = 30  # and at most every 30th beacon (a duty cycle stretches beacons to minutes)
ASKED_AGAIN = 0.5  # asked for, a certificate or signed beacon at most every half interval
DONE_EVERY = 2.5  # landed with the mission flown: a beacon every this many intervals


@dataclass(frozen=True)
class Cadence:
    """How often beacons go on a link, and what follows from it.

    ``interval_s``: the configured interval, stretched on duty-cycled links so beacons use at
    most 5 % of the budget (EU868 SF9: one beacon per ~5 minutes); ``signed_every_s``: a
    signed beacon at least this often (5 minutes, or every 30th beacon); ``asked_every_s``:
    how often we answer requests for our certificate or signed beacon (and refuse runs of
    drones we do not know yet) -- half the *configured* interval, at least 2 s: discovery
    must not wait for a duty cycle's minutes (its budget spaces the frames itself);
    ``silence_s``: how long a peer may go unheard in the normal course (beacons are deferred
    up to three intervals while runs are on the air, and jittered; measurements age
    ``FRESH_S``); ``done_s``: the interval once the mission is flown and the drone has
    landed (:attr:`OwnBeacon.done`) -- nobody compares with it any more, yet it stays heard
    (1.3 x 2.5 intervals and a deferral of half of one stay under ``silence_s``), so peers
    need not take it for a drone fallen silent nor re-learn it."""

    interval_s: float
    signed_every_s: float
    asked_every_s: float
    silence_s: float
    done_s: float

    @classmethod
    def of(cls, profile: LinkProfile, configured_s: float) -> Cadence:
        interval = beacon_interval(profile, configured_s)
        return cls(
            interval,
            max(SIGNED_EVERY_S, SIGNED_EVERY * interval),
            max(2.0, ASKED_AGAIN * configured_s),
            4.0 * interval + FRESH_S,
            DONE_EVERY * interval,
        )


@dataclass(frozen=True)
class OwnBeacon:
    """What our position beacon says now (the companion's view of itself)."""

    lat: int
    lon: int
    alt_m: int
    on_ground: bool
    suite: Suite
    version: int
    slots: Slots
    segments: int
    done: bool = False  # landed with its mission flown (not sent: it beacons less often)


class BeaconSender:
    """Sends our beacons; owns their stamps, the signing schedule and the counts."""

    def __init__(
        self,
        node: int,
        endpoint: LinkEndpoint,
        identity: Identity,
        beacon_keys: BeaconKeys,
        keys_hash: bytes,
        store: StateStore,
        neighbours: Neighbours,
        cadence: Cadence,
    ) -> None:
        self.node = node
        self.endpoint = endpoint
        self.clock = endpoint.clock
        self.identity = identity
        self.beacon_keys = beacon_keys
        self.keys_hash = keys_hash
        self.store = store
        self.neighbours = neighbours
        self.cadence = cadence
        self.bytes_sent = 0  # beacon payloads we sent (position and certificate)
        self.sent = dict.fromkeys(BeaconKind, 0)
        self._order: int | None = None  # (time, counter) of our last beacon
        self._signed_at = -math.inf  # our last signed beacon
        self._sign_next = True  # the next beacon is a signed one
        self._cert_sent = -math.inf
        self._cert_wanted = False  # ask for theirs with our next certificate
        self._now = asyncio.Event()
        self._cert_now = asyncio.Event()
        self._cert_now.set()  # our certificate, then a signed beacon: peers can check us at once

    # ------------------------------------------------------------------ asked of it

    def announce(self) -> None:
        """A position beacon at once (after a jitter): take-off, a new peer, new slots."""
        self._now.set()

    def send_certificate(self, *, ask: bool = False) -> None:
        """Our certificate beacon soon; ``ask``: it asks for the hearers' certificates too."""
        self._cert_wanted = self._cert_wanted or ask
        self._cert_now.set()

    def want_signed(self) -> None:
        """A signed beacon next (rate-limited): somebody lacks our beacon key."""
        if self.clock.now() - self._signed_at >= self.cadence.asked_every_s:
            self._sign_next = True
            self._now.set()

    # ------------------------------------------------------------------ its loops

    async def certificates(self) -> None:
        """Our certificate beacon when asked -- at most every half a beacon interval (a
        stranger's made-up beacons cost us at most that)."""
        while True:
            await self._cert_now.wait()
            wait = self._cert_sent + self.cadence.asked_every_s - self.clock.now()
            # an answer right after the question would meet the asker's next frame
            await self.clock.sleep(max(wait, 0.0) + _JITTER.uniform(0.1, 1.0))
            self._cert_now.clear()
            want, self._cert_wanted = self._cert_wanted, False
            self._cert_sent = self.clock.now()
            await self._send(CertBeacon(self.identity.cert, want).encode(), BeaconKind.CERTIFICATE)

    async def positions(
        self, content: Callable[[], OwnBeacon | None], busy: Callable[[], bool]
    ) -> None:
        """Beacon every interval (random phase and jitter: drones that beacon in lockstep
        collide on every beacon), and at once when announced -- on a duty-cycled link the
        interval is minutes, discovery must not wait for it.  ``busy``: a run is on the air
        (a beacon now would only collide with its frames): it is looked at again a moment
        later, for up to half an interval -- in a busy sky the channel is never free, and a
        beacon deferred by whole intervals left peers unheard for 40 s, which the fail-safe
        must take as flying straight at us (the link sends beacons ahead of run data);
        ``content`` None: no position from the autopilot yet (beacon once there is one); a
        drone landed with its mission flown beacons every ``Cadence.done_s`` (busy_ten: half
        the beacons of the drones that landed first came after their landing, 4.5 KB each)."""
        wait = _JITTER.uniform(0, self.cadence.interval_s)
        deferred = 0.0
        while True:
            with contextlib.suppress(TimeoutError):
                await self.clock.wait_for(self._now.wait(), wait)
            urgent = self._now.is_set()
            if urgent:
                self._now.clear()
                await self.clock.sleep(_JITTER.uniform(0.0, 1.0))  # do not answer in chorus
            if busy() and not urgent and deferred < self.cadence.interval_s / 2:
                wait = min(_JITTER.uniform(0.5, 1.5), self.cadence.interval_s / 4)
                deferred += wait
                continue
            own = content()
            if own is None:
                wait = 1.0  # (on a duty-cycled link the interval would lose minutes)
                continue
            deferred = 0.0
            await self._send(*self._position(own))
            every = self.cadence.done_s if own.done else self.cadence.interval_s
            wait = every * _JITTER.uniform(0.7, 1.3)

    # ------------------------------------------------------------------ inside

    def _stamp(self) -> tuple[int, int]:
        """(time, counter) of our next beacon: together they only ever grow, also across
        restarts (the last pair is kept on disk), so a peer never takes a fresh beacon of
        ours for a replay."""
        now = int(self.clock.wall()) << 8
        if self._order is None:  # the first beacon of this start
            self._order = self.store.last_counter(OWN) or 0
        self._order = max(self._order + 1, now)
        self.store.set_counter(OWN, self._order)
        return self._order >> 8, self._order & 0xFF

    def _position(self, own: OwnBeacon) -> tuple[bytes, BeaconKind]:
        """Our position beacon (:mod:`companion.neighbours.beacon`): signed when one is due (it
        carries our beacon key and keys hash), else tagged for every neighbour we share a key
        with."""
        time_s, counter = self._stamp()
        beacon = Beacon(
            own.lat,
            own.lon,
            own.alt_m,
            own.on_ground,
            frozenset({own.suite}),
            own.version,
            time_s,
            counter,
            own.slots,
            size_class(own.segments),
        )
        now = self.clock.now()
        tags = self.neighbours.tag_keys(self.clock.wall() - self.cadence.silence_s)
        if self._sign_next or now - self._signed_at >= self.cadence.signed_every_s:
            self._sign_next, self._signed_at = False, now
            signed = beacon.signed(
                self.node, self.identity.key, self.beacon_keys.public, self.keys_hash, tags
            )
            return signed, BeaconKind.SIGNED
        return beacon.tagged(self.node, tags), BeaconKind.TAGGED

    async def _send(self, payload: bytes, kind: BeaconKind) -> None:
        with contextlib.suppress(LinkError):
            await self.endpoint.beacon(payload)
            self.bytes_sent += len(payload)
            self.sent[kind] += 1
