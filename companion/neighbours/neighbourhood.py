"""The drones around us: their beacons heard, the peers they make, and how soon each could be
here.

Only a verified beacon of a trusted drone makes or moves a
:class:`~companion.neighbours.peers.Peer` (docs/security.md, "Beacons"); an untrusted drone is
logged, or reported as an intruder; a drone whose beacons lack something (its certificate, a
tag for us) is asked for it, less and less often.  :class:`Neighbourhood` also says what our
own position beacon says (:mod:`companion.neighbours.sender` sends it) and keeps the OT setups
we share with each peer.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from companion.auth.trust import UnknownPeers
from companion.context import Context
from companion.events import EventKind, PeerHeard, Stranger
from companion.mission.ground import distance_m
from companion.mission.own_flight import OwnFlight
from companion.neighbours.peers import Peer, time_to_meet
from companion.neighbours.registry import NO_CERTIFICATE, UNHEARD, Heard, Hearing, Neighbours
from companion.neighbours.sender import BeaconSender, Cadence, OwnBeacon
from companion.radio.endpoint import LinkEndpoint
from protocol.ot.setup import ChooserSetup, HolderSetup

log = logging.getLogger("companion")
ALERT_EVERY_S = 60.0  # an untrusted drone is reported at most this often (policy "alert")
ASK_BACKOFF_S = 30.0  # asking a drone again for what its beacons lack: at most this far apart
# (or four beacon intervals where a duty cycle stretches them) -- at 30 % loss one exchange
# of certificates fails about one time in two, and a backoff to 5 minutes left a drone
# unknown to its peer for 6 minutes in about one replay in fifty (it took off uncompared)


class Neighbourhood:
    """Peers from beacons (see the module).  ``on_slots(peer, new)``: a peer's announced
    altitude slots changed (``new``: it was just met); ``on_news()``: a peer was heard."""

    def __init__(
        self,
        ctx: Context,
        endpoint: LinkEndpoint,
        flight: OwnFlight,
        registry: Neighbours,
        sender: BeaconSender,
        cadence: Cadence,
    ) -> None:
        self.ctx = ctx
        self.settings = ctx.settings
        self.endpoint = endpoint
        self.flight = flight
        self.vehicle = flight.vehicle
        self.registry = registry
        self.sender = sender
        self.cadence = cadence
        self.peers: dict[int, Peer] = {}
        self.holder_setups: dict[int, HolderSetup] = {}  # peer -> ours as Alice
        self.chooser_setups: dict[int, dict[bytes, ChooserSetup]] = {}  # peer -> ours as Bob
        self.rejected: dict[str, int] = {}  # beacons dropped, by reason
        self.on_slots: Callable[[Peer, bool], None] = lambda peer, new: None
        self.on_news: Callable[[], None] = lambda: None
        self._ignored: set[bytes] = set()  # untrusted drones logged already
        self._alerted: dict[int, float] = {}
        self._asking: dict[int, tuple[float, float]] = {}  # node -> (next ask, interval)

    def own_beacon(self) -> OwnBeacon | None:
        """What our position beacon says now (None: no position from the autopilot yet)."""
        lat, lon, alt = self.vehicle.position
        if (lat, lon) == (0, 0):
            return None
        return OwnBeacon(
            lat,
            lon,
            round(alt),
            self.vehicle.on_ground,
            self.settings.suite,
            self.flight.version,
            self.flight.slots(),
            self.flight.own_size(),
            self.flight.done,
        )

    async def listen(self) -> None:
        """Every beacon the radio hears, checked and acted on."""
        while True:
            src, payload = await self.endpoint.beacons.get()
            if src == self.settings.node:
                continue
            self.heard(self.registry.hear(src, payload, self.ctx.clock.wall()))

    def heard(self, hearing: Hearing) -> None:
        """Act on one beacon: only a verified beacon of a trusted drone makes or moves a peer."""
        src = hearing.node
        if hearing.kind is Heard.REJECTED:
            self.rejected[hearing.reason] = self.rejected.get(hearing.reason, 0) + 1
            log.debug(
                "node %d: beacon from %d dropped: %s", self.settings.node, src, hearing.reason
            )
        elif hearing.kind is Heard.UNKNOWN:
            if not self.may_ask(src):
                return
            if hearing.reason == NO_CERTIFICATE:  # ask for it (ours goes with the question)
                self.sender.send_certificate(ask=True)
            if hearing.reason == UNHEARD:
                # It has our key but has not heard us lately: a beacon of ours at once (in a
                # busy sky 38 % of beacons were signed ones, 138 bytes, mostly for this).
                self.sender.announce()
                return
            # Its beacon key or its tag for us is missing: with our signed beacon it gets our
            # key (and tags for us), and it answers a new key with its own signed beacon.
            self.sender.want_signed()
        elif hearing.kind is Heard.UNTRUSTED:
            self._untrusted(hearing)
        elif hearing.kind is Heard.CERTIFICATE:
            if hearing.want:  # it cannot check somebody's beacons: ours, perhaps
                self.sender.send_certificate()
                self.sender.want_signed()
            if hearing.then is not None:  # its signed beacon, heard before the certificate
                self.heard(hearing.then)
        else:
            self._moved(hearing)

    def _moved(self, hearing: Hearing) -> None:
        """A verified beacon of a trusted drone: the peer made or moved."""
        src, beacon, neighbour = hearing.node, hearing.beacon, hearing.neighbour
        assert beacon is not None and neighbour is not None
        if neighbour.knows_us:
            self._asking.pop(src, None)  # nothing to ask it for any more
        if hearing.new_keys:  # a new beacon key: it may lack ours
            self.sender.want_signed()
        now = self.ctx.clock.now()
        peer = self.peers.get(src)
        if peer is not None and peer.identity != neighbour.fingerprint:
            self.forget(src)  # another drone holds this node id now
            peer = None
        new_peer = peer is None
        if peer is None:
            peer = self.peers[src] = Peer(
                src, beacon, now, identity=neighbour.fingerprint, met_at=now
            )
            self.ctx.record(
                EventKind.PEER,
                PeerHeard(
                    peer=src,
                    on_ground=beacon.on_ground,
                    drone=neighbour.fingerprint.hex(),
                    operator=neighbour.operator.name,
                ),
            )
            self.sender.announce()  # let it hear us without waiting an interval
        elif hearing.new_keys:
            self.drop_setups(src)  # it restarted (a new beacon key): they are gone on its side
        slots_changed = peer.beacon.slots != beacon.slots or new_peer
        if beacon.slots.top > peer.beacon.slots.top:
            peer.raised = True  # it climbed above what it flew when first heard
        # Its stamp is whole Unix seconds (truncated): the position is half a second older
        # on average; in link time (the wall clock is link time plus an offset).
        made_at = beacon.time + 0.5 - (self.ctx.clock.wall() - now)
        peer.heard(beacon, now, self.vehicle.position[:2], made_at=made_at)
        if slots_changed:
            self.on_slots(peer, new_peer)
        self.on_news()

    def may_ask(self, node: int) -> bool:
        """Whether to ask again for what a node's beacons lack (its certificate, or its tag for
        us): at once the first time, then less and less often (to ``ASK_BACKOFF_S``, or four
        beacon intervals on a duty-cycled link, at most a signed-beacon period) while it
        stays so -- a drone that does not trust us would otherwise make us ask at every
        beacon."""
        now = self.ctx.clock.now()
        due, interval = self._asking.get(node, (now, self.cadence.asked_every_s / 2))
        if now < due:
            return False
        duty_cycled = self.endpoint.profile.duty_cycle is not None
        longest = 4 * self.cadence.interval_s if duty_cycled else ASK_BACKOFF_S
        longest = min(self.cadence.signed_every_s, longest)
        interval = min(2 * interval, longest)
        self._asking[node] = (now + interval, interval)
        return True

    def _untrusted(self, hearing: Hearing) -> None:
        """A drone the trust store does not accept: never deconflicted with; logged once, and
        with policy ``alert`` reported as an intruder (at most every ALERT_EVERY_S)."""
        assert hearing.cert is not None  # an untrusted drone is one whose certificate we refused
        drone = hearing.cert.fingerprint
        if drone not in self._ignored:
            self._ignored.add(drone)
            self.ctx.record(
                EventKind.UNTRUSTED,
                Stranger(peer=hearing.node, drone=drone.hex(), reason=hearing.reason),
            )
        if self.registry.trust.unknown is not UnknownPeers.ALERT or hearing.beacon is None:
            return
        now = self.ctx.clock.now()
        if now - self._alerted.get(hearing.node, -math.inf) >= ALERT_EVERY_S:
            self._alerted[hearing.node] = now
            b = hearing.beacon
            distance = distance_m(self.vehicle.position[:2], (b.lat, b.lon))
            here = Stranger(hearing.node, drone.hex(), None, b.lat, b.lon, b.alt_m, round(distance))
            self.ctx.record(EventKind.INTRUDER, here)

    def knows_us(self, peer: Peer) -> bool:
        """Its tagged beacons carry a tag for us: it holds our beacon key (it heard us)."""
        neighbour = self.registry.get(peer.node)
        return neighbour is not None and neighbour.knows_us

    def introducing(self, peer: Peer, now: float) -> bool:
        """A peer we know that does not know us yet (it lacks our certificate or beacon
        key), met less than a signed-beacon period ago: the run waits for the introduction,
        and so does a take-off held for comparisons -- not for ever (a drone that does not
        trust us never will)."""
        return not self.knows_us(peer) and now - peer.met_at < self.cadence.signed_every_s

    def silent_for(self, peer: Peer) -> float:
        """Seconds since the peer was last heard if it has fallen silent, else 0."""
        age = self.ctx.clock.now() - peer.heard_at
        return age if age > self.cadence.silence_s else 0.0

    def still_heard(self, node: int) -> bool:
        """The peer has not fallen silent (:attr:`Cadence.silence_s`): a run's message the link
        gave up on goes again while it is heard -- a jammer, not a drone gone."""
        peer = self.peers.get(node)
        return peer is not None and not self.silent_for(peer)

    def peer_speed(self, peer: Peer) -> float:
        """The speed the fail-safe assumes for a peer: its measured speed, at least the
        floor; an airborne peer not measured lately (heard too seldom, or silent since) may
        fly at cruise speed whatever it did when last measured."""
        floor = self.settings.failsafe.floor_m_s
        if not peer.beacon.on_ground and (not peer.measured or self.silent_for(peer) > 0):
            floor = max(floor, self.settings.cruise_m_s)
        return max(peer.speed_m_s, floor)

    def peer_pace(self, peer: Peer) -> float:
        """How fast the peer may fly through the path it showed: its speed, at least cruise."""
        return max(self.peer_speed(peer), self.settings.cruise_m_s)

    def urgency(self, peer: Peer) -> float:
        """Seconds until the peer could be here (:func:`time_to_meet`: at the measured rate
        our distance shrinks, where fresh; else flying straight at us)."""
        return self._meet(peer, measured=True)

    def earliest(self, peer: Peer) -> float:
        """Seconds until the peer could be here even if it turned straight at us now: a
        bound, not an expectation -- the measured closing rate left out, and the peer as
        much closer as it could have flown since its last beacon (at SF12 beacons are
        minutes apart)."""
        return self._meet(peer, measured=False, silent_after_s=0.0)

    def _meet(self, peer: Peer, *, measured: bool, silent_after_s: float | None = None) -> float:
        return time_to_meet(
            self.vehicle.position[:2],
            self.vehicle.speed_m_s,
            peer,
            floor_m_s=self.settings.failsafe.floor_m_s,
            peer_floor_m_s=self.peer_speed(peer),
            now=self.ctx.clock.now(),
            silent_after_s=self.cadence.silence_s if silent_after_s is None else silent_after_s,
            measured=measured,
        )

    def forget(self, node: int) -> None:
        self.peers.pop(node, None)
        self.drop_setups(node)

    def drop_setups(self, node: int) -> None:
        """The OT setups we share with ``node`` (both roles)."""
        self.holder_setups.pop(node, None)
        self.chooser_setups.pop(node, None)
