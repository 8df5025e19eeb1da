"""The companion's beacons: what its own say (sent by :mod:`companion.neighbours.sender`), and
hearing its neighbours'.

What a heard beacon does: only a verified beacon of a trusted drone makes or moves a
:class:`~companion.neighbours.peers.Peer` (docs/security.md, "Beacons"); an untrusted drone is
logged, or reported as an intruder.
"""

from __future__ import annotations

import logging
import math
import random

from companion.app.core import ASK_BACKOFF_S
from companion.auth.trust import UnknownPeers
from companion.events import EventKind, PeerHeard, Stranger
from companion.mission.edits import Edits
from companion.neighbours.peers import Peer, distance_m
from companion.neighbours.registry import NO_CERTIFICATE, Heard, Hearing
from companion.neighbours.sender import OwnBeacon

log = logging.getLogger("companion")
_JITTER = random.SystemRandom()
ALERT_EVERY_S = 60.0  # an untrusted drone is reported at most this often (policy "alert")


class Beaconing(Edits):
    """Sending and hearing beacons."""

    def _own_beacon(self) -> OwnBeacon | None:
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
            self.version,
            self._slots(),
            self._own_size(),
        )

    def _on_air(self) -> bool:
        """A run is on the air (ours or an answer): a beacon would only collide with it."""
        return bool(self._sessions) or self.endpoint.busy()

    async def _listen(self) -> None:
        while True:
            src, payload = await self.endpoint.beacons.get()
            if src == self.settings.node:
                continue
            self._heard(self.neighbours.hear(src, payload, self.clock.wall()))

    def _heard(self, hearing: Hearing) -> None:
        """Act on one beacon: only a verified beacon of a trusted drone makes or moves a peer."""
        src = hearing.node
        if hearing.kind is Heard.REJECTED:
            self.rejected[hearing.reason] = self.rejected.get(hearing.reason, 0) + 1
            log.debug(
                "node %d: beacon from %d dropped: %s", self.settings.node, src, hearing.reason
            )
            return
        if hearing.kind is Heard.UNKNOWN:
            if not self._may_ask(src):
                return
            if hearing.reason == NO_CERTIFICATE:  # ask for it (ours goes with the question)
                self.sender.send_certificate(ask=True)
            # Its beacon key or its tag for us is missing: with our signed beacon it gets our
            # key (and tags for us), and it answers a new key with its own signed beacon.
            self.sender.want_signed()
            return
        if hearing.kind is Heard.UNTRUSTED:
            self._untrusted(hearing)
            return
        if hearing.kind is Heard.CERTIFICATE:
            if hearing.want:  # it cannot check somebody's beacons: ours, perhaps
                self.sender.send_certificate()
                self.sender.want_signed()
            if hearing.then is not None:  # its signed beacon, heard before the certificate
                self._heard(hearing.then)
            return
        beacon, neighbour = hearing.beacon, hearing.neighbour
        assert beacon is not None and neighbour is not None
        if neighbour.knows_us:
            self._asking.pop(src, None)  # nothing to ask it for any more
        if hearing.new_keys:  # a new beacon key: it may lack ours
            self.sender.want_signed()
        now = self.clock.now()
        peer = self.peers.get(src)
        if peer is not None and peer.identity != neighbour.fingerprint:
            self._forget(src)  # another drone holds this node id now
            peer = None
        new_peer = peer is None
        if peer is None:
            peer = self.peers[src] = Peer(
                src, beacon, now, identity=neighbour.fingerprint, met_at=now
            )
            self.record(
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
            self._drop_setups(src)  # it restarted (a new beacon key): they are gone on its side
        slots_changed = peer.beacon.slots != beacon.slots or new_peer
        if beacon.slots.top > peer.beacon.slots.top:
            peer.raised = True  # it climbed above what it flew when first heard
        # Its stamp is whole Unix seconds (truncated): the position is half a second older
        # on average; in link time (the wall clock is link time plus an offset).
        made_at = beacon.time + 0.5 - (self.clock.wall() - now)
        peer.heard(beacon, now, self.vehicle.position[:2], made_at=made_at)
        # Our raises keep clear of every peer's slots (a run compared the altitudes we fly
        # without them); of two drones that raised into each other's slots the higher node
        # moves, so two never climb past each other in turn.  A peer heard for the first
        # time is news to both.
        raised = bool(self._ahead(self.raises)) and (new_peer or src < self.settings.node)
        # A raised higher node that moved keeps clear of us: no chasing it (its move may
        # be one away from our raise).
        yields = peer.raised and src > self.settings.node and not new_peer
        ours = (bool(peer.conflicts) or src in self.precaution) and not yields
        if slots_changed and (ours or raised):
            self._spawn(self._replan(f"peer {src} announced altitude slots"))
        self._wake.set()

    def _may_ask(self, node: int) -> bool:
        """Whether to ask again for what a node's beacons lack (its certificate, or its tag for
        us): at once the first time, then less and less often (to ``ASK_BACKOFF_S``, or four
        beacon intervals on a duty-cycled link, at most a signed-beacon period) while it
        stays so -- a drone that does not trust us would otherwise make us ask at every
        beacon."""
        now = self.clock.now()
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
            self.record(
                EventKind.UNTRUSTED,
                Stranger(peer=hearing.node, drone=drone.hex(), reason=hearing.reason),
            )
        if self.neighbours.trust.unknown is not UnknownPeers.ALERT or hearing.beacon is None:
            return
        now = self.clock.now()
        if now - self._alerted.get(hearing.node, -math.inf) >= ALERT_EVERY_S:
            self._alerted[hearing.node] = now
            b = hearing.beacon
            distance = distance_m(self.vehicle.position[:2], (b.lat, b.lon))
            here = Stranger(hearing.node, drone.hex(), None, b.lat, b.lon, b.alt_m, round(distance))
            self.record(EventKind.INTRUDER, here)
