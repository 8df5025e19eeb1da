"""Bob's side: answering a peer's run request.

A request is admitted only once it has shown who asks (a trusted certificate, a signature, a
fresh time, not a replay) and that the run is plausible and within the peer's budget; then
Bob answers with the part of his path still to fly (:func:`companion.runs.exchange.serve_bob`).
What goes back otherwise is a one-byte abort code or a signed refusal, never anything about
the path.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from companion.auth.certificate import Certificate
from companion.auth.session import AuthenticationError, Identity, Init, Refusal, Responder, Route
from companion.context import Context
from companion.errors import CompanionError
from companion.events import Answered, EventKind, PeerFailure, PeerNote
from companion.mission.ground import COVER_ALL, along_segment, distance_m
from companion.mission.items import point_as_segment
from companion.mission.own_flight import OwnFlight
from companion.mission.schedule import (
    T_RANGE_S,
    piece_volumes,
    route_volumes,
    run_volumes,
    split_long,
)
from companion.neighbours.beacon import MAX_SIZE_CLASS
from companion.neighbours.neighbourhood import Neighbourhood
from companion.neighbours.peers import Peer
from companion.radio.arq import LinkError
from companion.radio.endpoint import LinkEndpoint
from companion.radio.frames import AbortCode
from companion.roles import Role
from companion.runs.budget import BOB, MAX_RUN_WORK, BudgetExceeded, RunLedger, run_work
from companion.runs.exchange import RunReport, serve_bob
from companion.runs.progress import RunProgress
from companion.runs.turns import ANSWER_FULL, ANSWER_NEAR, Air
from companion.state import StateStore
from protocol.errors import ProtocolError
from protocol.geo.grid import GridKind
from protocol.geo.volumes import Route as PathRoute
from protocol.geo.volumes import pad_route
from protocol.intersection import Bob
from protocol.messages import Hello
from protocol.ot.setup import ChooserSetup
from protocol.paper.keys import BobKeys

log = logging.getLogger("companion")
SETUPS_PER_PEER = 2
# A request's box is made this long at most before its first fragment reaches us (the
# requester's listen-before-talk and the frame's own airtime).
REQUEST_LEAD_S = 10.0
# A request's first frame may wait this long for a busy channel before it leaves (ten drones
# on one US915 channel: 30-50 s, and the request was refused as stale after 30).  Replays
# stay caught: the replay store keeps requests for twice the whole window.
ACCESS_WAIT_S = 60.0


@dataclass
class Cover:
    """How much of Alice's horizon our answer covers, in eighths (``COVER_ALL``: all of
    it), known once our path is cut for her (it goes back sealed, with our first reply)."""

    eighths: int = COVER_ALL


class Responding(NamedTuple):
    """Who answers: our identity, our paper-suite keys (if we answer that suite), the boot
    nonce of this start (peers drop our setups when it changes) and the state on disk (the
    replay cache)."""

    identity: Identity
    bob_keys: BobKeys | None
    boot: bytes
    store: StateStore


class BobAnswers:
    """Answering as Bob (:meth:`serve`).  ``on_done()``: an answer ended (the radio is
    free for our own runs)."""

    def __init__(
        self,
        ctx: Context,
        endpoint: LinkEndpoint,
        me: Responding,
        flight: OwnFlight,
        neighbourhood: Neighbourhood,
        air: Air,
        ledger: RunLedger,
        on_done: Callable[[], None],
    ) -> None:
        self.ctx = ctx
        self.settings = ctx.settings
        self.clock = ctx.clock
        self.record = ctx.record
        self.endpoint = endpoint
        self.identity, self.bob_keys, self.boot, self.store = me
        self.flight = flight
        self.vehicle = flight.vehicle
        self.neighbourhood = neighbourhood
        self.air = air
        self.ledger = ledger
        self._on_done = on_done
        self._unknown_refused = -math.inf  # when we last refused a drone we do not know

    async def serve(self) -> None:
        """Every run request the radio brings, answered in a task of its own."""
        while True:
            peer, session = await self.endpoint.accept()
            self.ctx.spawn(self._answer(peer, session), "answer")

    def _bob_path(self, hello: Hello, cover: Cover) -> PathRoute:
        """What we answer with: the rest of the mission the vehicle holds, padded to our size
        class (:meth:`OwnFlight.own_size`) -- in a near run exactly the segments Alice asked
        for (:meth:`_near_size`; cut or padded), their cover of her horizon put in ``cover``
        -- with its bands (on her grid) and windows (after her epoch) when she asks for
        them."""
        size = self._near_size(hello) if hello.horizon_m > 0 else self.flight.own_size()
        route = self._route(hello, size, cover)
        return pad_route(route, size) if route.segments < size else route

    def _near_size(self, hello: Hello) -> int:
        """How many segments a near run of Alice's takes of our path: as many as she asked
        for (``Hello.n``, chosen from public facts), else as many as she compares or our size
        class, the smaller -- public numbers all: the run's size on the air shows nothing of
        our path (docs/security.md, D8)."""
        return hello.n or min(hello.m, self.flight.own_size())

    def _route(self, hello: Hello, size: int, cover: Cover) -> PathRoute:
        """Our remaining path from here, in a near run cut to ``size`` segments."""
        start, path = self.flight.remaining_flown()
        path, cover.eighths = self.flight.near_answer(
            self.flight.from_here(path), hello.horizon_m, size
        )
        points = point_as_segment(path)  # hovering: a point
        volumes = hello.volumes
        if not (volumes.bands or volumes.windows):
            return PathRoute(tuple(points))
        tolerance = self.settings.separation.tolerance
        resolution = hello.grid.resolution_mm
        since = self.flight.wall_of_state() - volumes.epoch_s
        if len(path) < 2:  # a point: here, from now on
            alt = self.vehicle.position[2]
            cells = 1000.0 / resolution
            band = (
                math.floor((alt - tolerance.altitude_m) * cells),
                math.ceil((alt + tolerance.altitude_m) * cells),
            )
            return PathRoute(tuple(points), (band,), ((math.floor(since), T_RANGE_S),))
        schedule = self.flight.held_schedule(start)
        count = len(path) - 1
        if count < size and volumes.windows:
            # The run is padded to its size anyway: its free slots cut our longest legs in
            # time, each part with its own window (companion.mission.schedule.split_long).
            pieces = split_long(schedule, start, count, size)
            k0, share0, _ = pieces[0]
            parts = [along_segment(path[k0 - start], path[k0 - start + 1], share0)]
            for k, _, end in pieces:
                parts.append(along_segment(path[k - start], path[k - start + 1], end))
            bands, windows = piece_volumes(schedule, pieces, resolution, since, tolerance)
            return PathRoute(tuple(parts), bands, windows)
        bands, windows = route_volumes(schedule, start, count, resolution, since, tolerance)
        return PathRoute(tuple(points), bands, windows)

    async def _answer(self, peer: int, session: int) -> None:
        """Answer a run request -- only once it has shown who asks (a trusted certificate, a
        signature, a fresh time, not a replay) and that the run is plausible and within the
        budget: nobody else makes us work, and what goes back is a one-byte abort code or a
        signed refusal, never anything about our path."""
        setups = self.neighbourhood.chooser_setups.setdefault(peer, {})
        try:
            request = await self.endpoint.receive(peer, session)
            admitted = await self._admit(peer, session, request)
            if admitted is None:
                return
            report, bob = await self._serve_admitted(peer, session, *admitted, setups)
        except AuthenticationError as exc:
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, auth=str(exc)))
            return
        except (ProtocolError, CompanionError) as exc:
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, error=str(exc)))
            return
        except Exception as exc:  # nothing may stop the companion
            log.exception("node %d: answering %d failed", self.settings.node, peer)
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, error=f"internal: {exc!r}"))
            return
        finally:
            self._on_done()
            while len(setups) > SETUPS_PER_PEER:  # the oldest go first
                setups.pop(next(iter(setups)))
        if report.refused is not None:
            self.record(EventKind.REFUSED, PeerNote(peer=peer, reason=report.refused.name))
            return
        self.record(
            EventKind.ANSWERED,
            Answered(
                peer=peer,
                bytes=report.bytes_sent,
                auth_bytes=report.auth_bytes_sent,
                guard_bytes=bob.guard_bytes,
            ),
        )

    async def _serve_admitted(
        self,
        peer: int,
        session: int,
        responder: Responder,
        hello: Hello,
        ticket: int,
        setups: dict[bytes, ChooserSetup],
    ) -> tuple[RunReport, Bob]:
        """An admitted request, answered once the radio is ours (answers first, near before
        full); the run is refunded if Alice never got our first reply."""
        self.air.answers_waiting += 1
        waiting = True
        try:
            async with self.air.turns.turn(ANSWER_NEAR if hello.horizon_m > 0 else ANSWER_FULL):
                self.air.answers_waiting, waiting = self.air.answers_waiting - 1, False
                self.air.sessions += 1
                separation = run_volumes(
                    self.settings.separation, hello.grid.resolution_mm, 0
                ).separation
                cover = Cover()
                bob = Bob(
                    functools.partial(self._bob_path, cover=cover),
                    keys=self.bob_keys,
                    setups=setups,
                    geographic=True,
                    separation=separation,
                )
                try:
                    with RunProgress(self.settings.node, self.endpoint, peer, Role.BOB):
                        report = await serve_bob(
                            self.endpoint,
                            peer,
                            session,
                            bob,
                            secure=responder,
                            boot=self.boot,
                            cover=lambda: cover.eighths,
                            timeout=self.settings.run_timeout_s,
                            first=responder.init.hello,
                            alive=functools.partial(self.neighbourhood.still_heard, peer),
                        )
                finally:
                    self.air.sessions -= 1
                    if not responder.keyed:  # no first reply: Alice learnt nothing
                        self.ledger.refund(ticket)
        finally:
            if waiting:
                self.air.answers_waiting -= 1
        return report, bob

    async def _admit(
        self, peer: int, session: int, request: bytes
    ) -> tuple[Responder, Hello, int] | None:
        """The checks before any work on a request, cheapest first.  None: the request was
        dropped, aborted (code only) or refused (signed), and the session is closed."""
        wall = self.clock.wall()
        try:
            init = Init.parse(request)
        except AuthenticationError as exc:
            self.endpoint.abort(peer, session, AbortCode.AUTH)
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, auth=str(exc)))
            return None
        responder = Responder(self.identity, init, Route(peer, self.settings.node, session))
        neighbour = self.neighbourhood.registry.get(peer)
        known = self.neighbourhood.peers.get(peer)
        if neighbour is None or known is None or known.identity != neighbour.fingerprint:
            await self._unknown(peer, session, responder)
            return None
        if not self._fresh(peer, session, responder, neighbour.cert, wall):
            return None
        try:
            hello = Hello.from_bytes(init.hello)
        except ProtocolError as exc:
            proof = responder.abort_proof(AbortCode.PROTOCOL)
            self.endpoint.abort(peer, session, AbortCode.PROTOCOL, proof)
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, error=str(exc)))
            return None
        operator = neighbour.operator
        began = self.endpoint.arrived_at(peer, session)
        code = self._refusal(peer, hello, known, operator.max_segments, began)
        if code is not None:
            await self._refuse(peer, session, responder, code)
            return None
        try:
            ticket = self.ledger.admit(
                known.identity,
                operator.key.fingerprint,
                operator.max_runs_per_hour,
                wall,
                BOB,
                bits=hello.m,
                operator_bits=operator.max_answer_bits_per_hour,
            )
        except BudgetExceeded as exc:
            self.record(EventKind.BUDGET, PeerFailure(peer=peer, error=str(exc)))
            await self._refuse(peer, session, responder, Refusal.BUDGET)
            return None
        known.role = Role.BOB
        known.conflicts.clear()  # as Bob we do not adjust for this peer
        return responder, hello, ticket

    async def _unknown(self, peer: int, session: int, responder: Responder) -> None:
        """A request from a drone we cannot check: an untrusted one is ignored (not a word
        back); one whose certificate (or beacon) we lack is told so -- signed, at most every
        half a beacon interval -- and asked for its certificate."""
        if self.neighbourhood.registry.untrusted(peer):
            self.endpoint.close_session(peer, session)
            return
        self.neighbourhood.sender.send_certificate(ask=True)
        now = self.clock.now()
        if now - self._unknown_refused >= self.neighbourhood.cadence.asked_every_s:
            self._unknown_refused = now
            await self._refuse(peer, session, responder, Refusal.UNKNOWN_PEER)
        else:
            self.endpoint.close_session(peer, session)

    def _fresh(
        self, peer: int, session: int, responder: Responder, cert: Certificate, wall: float
    ) -> bool:
        """Signed by ``cert``, made when its first frame could have left (a duty-cycled
        sender may wait up to a window for its budget, any sender ACCESS_WAIT_S for a busy
        channel) and answered once (the replay cache on disk outlives the window); else
        aborted with a proof."""
        skew = self.settings.max_clock_skew_s
        wait = self.endpoint.profile.budget_wait_s + ACCESS_WAIT_S
        try:
            responder.verify(cert, self.endpoint.arrived(peer, session), skew, wait)
            forget = wall - 2 * (skew + wait)
            if not self.store.first_request(responder.init.replay_key, wall, forget):
                raise AuthenticationError("a request answered before (a replay)")
        except AuthenticationError as exc:
            # Signed: the requester's link takes no abort without a proof (a stale request
            # of an honest drone learns at once; a forger's learns nothing new).
            proof = responder.abort_proof(AbortCode.AUTH)
            self.endpoint.abort(peer, session, AbortCode.AUTH, proof)
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, auth=str(exc)))
            return False
        return True

    def _refusal(
        self, peer: int, hello: Hello, known: Peer, max_segments: int, began: float
    ) -> Refusal | None:
        """The checks on an authenticated request before any work, cheapest first: the role,
        a radio that is not free, the size (its beacon's, its operator's limit, a fair run's
        work) and the box (``began``: link time its first fragment reached us); the refusal,
        or None to go on."""
        if known.role is Role.ALICE:
            if self.settings.node < peer:
                # Both took the pair as Alice (their views of who was on the ground crossed):
                # exactly one of a pair adjusts -- the lower node id keeps the role.
                return Refusal.ROLE
            self.record(
                EventKind.YIELDED, PeerNote(peer=peer, reason="the peer has the lower node id")
            )
        if self.air.too_busy_to_wait():  # (companion.runs.turns)
            return Refusal.BUSY
        allowed = min(max_segments, 1 << min(known.beacon.size_class, MAX_SIZE_CLASS))
        if hello.m > allowed:  # more than its beacon announced or its operator allows
            return Refusal.SIZE
        if hello.n and not hello.horizon_m:
            return Refusal.SIZE  # a size asked of a full run: our whole path or nothing
        n = hello.n or self.flight.own_size()
        if run_work(hello.m, n, hello.grid.range) > MAX_RUN_WORK:
            # More than a fair run (m x n x grid bits): Bob's CPU, memory and first reply
            # grow with it, and a refused run costs the asker nothing.
            return Refusal.SIZE
        if not self._plausible_box(hello, known, began):
            return Refusal.BOX
        return None

    def _plausible_box(self, hello: Hello, known: Peer, began: float) -> bool:
        """Alice's grid is centred where she is when her request begins: within what she can
        have flown since the last position her track of verified beacons makes plausible
        (:attr:`Peer.anchor`: a beacon that jumps faster than ``MAX_SPEED_M_S`` moves no
        box), or, as that request may take a minute to reach us whole on a busy channel,
        where that track had her when its first fragment arrived (``began``, give or take
        ``REQUEST_LEAD_S``: :meth:`Peer.plausible_at`); and within ``max_peer_range_m`` of us
        (a drone on our radio); it
        reaches no further than ``max_box_radius_m`` and is no finer than
        ``min_grid_resolution_mm``.  Bob's path is
        cut to her box, so a box elsewhere -- or one centred on her that spans a continent --
        would let a deviating Alice probe where Bob flies far from her.  The refusal depends
        on her request, her beacons and Bob's limits only, not on Bob's path."""
        grid = hello.grid
        if grid.kind is not GridKind.GEO:
            return False  # a drone's run is on the globe
        if grid.resolution_mm < self.settings.min_grid_resolution_mm:
            return False
        if grid.radius_m > self.settings.max_box_radius_m:
            return False
        if known.anchor is None:
            return False
        centre = (grid.ref_lat_e7, grid.ref_lon_e7)
        if distance_m(centre, self.vehicle.position[:2]) > self.settings.max_peer_range_m:
            return False  # not where a drone we hear on our radio can be
        if distance_m(centre, known.anchor[1]) <= known.reach_m(self.clock.now()):
            return True
        # (a busy channel: ten drones' requests came 631-1003 m from her last beacon, each
        # a whole wasted request and a late result)
        return known.plausible_at(centre, began, REQUEST_LEAD_S)

    async def _refuse(self, peer: int, session: int, responder: Responder, code: Refusal) -> None:
        self.record(EventKind.REFUSED, PeerNote(peer=peer, reason=code.name))
        try:
            await self.endpoint.send(peer, session, responder.refuse(code))
        except LinkError:
            pass
        finally:
            self.endpoint.close_session(peer, session)
