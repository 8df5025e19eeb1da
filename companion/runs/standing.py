"""What stands of our comparisons with each peer: whether one is due (we are its Alice, it is
in range, its path or ours changed since), and which of our segments a run has decided for
how long.  Alice's runs plan from it and the fail-safe watches what it leaves open."""

from __future__ import annotations

import math

from companion.mission.ground import distance_m
from companion.mission.own_flight import OwnFlight
from companion.neighbours.beacon import alice_of
from companion.neighbours.neighbourhood import Neighbourhood
from companion.neighbours.peers import Peer, Versions
from companion.roles import Role


class Standing:
    def __init__(self, flight: OwnFlight, neighbourhood: Neighbourhood) -> None:
        self.flight = flight
        self.vehicle = flight.vehicle
        self.neighbourhood = neighbourhood
        self.settings = flight.settings
        self.clock = flight.ctx.clock

    def pending(self, peer: Peer) -> bool:
        """We are Alice for this peer, it is in range, and its paths are not compared yet."""
        node = self.settings.node
        me = (self.vehicle.on_ground, node)
        them = (peer.beacon.on_ground, peer.node)
        if peer.role is Role.BOB:
            return False
        if peer.role is None and alice_of(me, them) != node:
            return False
        if self.settings.suite not in peer.beacon.suites:
            return False
        if self.vehicle.position[:2] == (0, 0):
            return False
        if distance_m(self.vehicle.position[:2], peer.position) > self.settings.initiation_range_m:
            return False
        if self.clock.now() >= peer.recheck_at:  # a hold for it asks again
            return True
        return peer.compared != self.versions(peer)

    def versions(self, peer: Peer) -> Versions:
        """What a comparison with ``peer`` compares: its mission, ours as planned, and those of
        our raises that come near its announced altitudes (:meth:`OwnFlight.raises_near`) --
        a run stands until one of them changes."""
        near = self.flight.raises_near(peer.beacon.slots)
        return peer.beacon.mission_version, self.flight.compare_version, near

    def due(self, peer: Peer, now: float) -> bool:
        """Pending, not waiting for a retry, and the peer can check our requests: its tagged
        beacons carry a tag for us (it holds our beacon key, so it heard us)."""
        return now >= peer.next_try and self.neighbourhood.knows_us(peer) and self.pending(peer)

    def near_expires(self, peer: Peer) -> float:
        """When the peer may be past the path its last near run showed (its horizon at
        :meth:`Neighbourhood.peer_pace` from the run's start); -inf without a near run."""
        if peer.near_run is None:
            return -math.inf
        started, horizon = peer.near_run
        return started + horizon / self.neighbourhood.peer_pace(peer)

    def decided(self, peer: Peer) -> set[int]:
        """Our segments whose comparison with ``peer`` stands: those settled (a full run
        compared them, or we leave them before the peer could come near), those a run found
        in conflict (a hit with part of its path is a hit with all of it), and those a near
        run cleared that we leave before the peer can be past the end of the path it showed
        (its horizon at its speed, at least cruise, less the margin).  A segment only a near
        run cleared is open again once that may no longer hold: the fail-safe watches it
        (:func:`companion.runs.failsafe.at_risk`)."""
        decided = peer.settled | (peer.covered & peer.conflicts)
        near = peer.covered - decided
        if not near or peer.near_run is None:
            return decided
        beyond = self.near_expires(peer) - self.clock.now() - self.settings.failsafe.margin_s
        if self.vehicle.on_ground and not self.vehicle.has_flown:
            return decided  # (take-off time unknown: windows never close)
        start = self.flight.remaining_path()[0]
        decided |= {k for k in near if k < start}  # flown already
        near = {k for k in near if k >= start}
        if not near:
            return decided
        schedule = self.flight.original_schedule(start)
        tolerance = self.settings.separation.tolerance
        for k in near:
            try:
                if schedule.window(k, tolerance)[1] < beyond:
                    decided.add(k)
            except IndexError:  # beyond the scheduled path
                continue
        return decided
