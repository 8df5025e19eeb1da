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

from companion.app.core import CompanionCore
from companion.auth.session import AuthenticationError, Init, Refusal, Responder, Route
from companion.errors import CompanionError
from companion.events import Answered, EventKind, PeerFailure, PeerNote
from companion.mission.items import point_as_segment
from companion.mission.schedule import T_RANGE_S, route_volumes, run_volumes
from companion.neighbours.beacon import MAX_SIZE_CLASS
from companion.neighbours.peers import Peer, distance_m
from companion.radio.arq import LinkError
from companion.radio.frames import AbortCode
from companion.runs.budget import BOB, MAX_RUN_WORK, BudgetExceeded, run_work
from companion.runs.exchange import serve_bob
from companion.runs.progress import RunProgress
from companion.runs.roles import Role
from companion.runs.turns import ANSWER_FULL, ANSWER_NEAR
from protocol.errors import ProtocolError
from protocol.geo.grid import GridKind
from protocol.geo.volumes import Route as PathRoute
from protocol.intersection import Bob
from protocol.messages import Hello

log = logging.getLogger("companion")
SETUPS_PER_PEER = 2


class BobAnswers(CompanionCore):
    """Answering as Bob."""

    async def _serve(self) -> None:
        while True:
            peer, session = await self.endpoint.accept()
            self._spawn(self._answer(peer, session))

    def _bob_path(self, hello: Hello) -> list[tuple[int, int]] | PathRoute:
        """What we answer with: the rest of the mission the vehicle holds, cut at Alice's
        horizon, with its bands (on her grid) and windows (after her epoch) when she asks
        for them."""
        start, path = self._remaining_flown()
        path = self._near(path, hello.horizon_m)
        points = point_as_segment(path)  # hovering: a point
        volumes = hello.volumes
        if not (volumes.bands or volumes.windows):
            return points
        tolerance = self.settings.separation.tolerance
        resolution = hello.grid.resolution_mm
        since = self._wall_of_state() - volumes.epoch_s
        if len(path) < 2:  # a point: here, from now on
            alt = self.vehicle.position[2]
            cells = 1000.0 / resolution
            band = (
                math.floor((alt - tolerance.altitude_m) * cells),
                math.ceil((alt + tolerance.altitude_m) * cells),
            )
            return PathRoute(tuple(points), (band,), ((math.floor(since), T_RANGE_S),))
        schedule = self._schedule(self.mission, self.flown, start, self.vehicle.current_item)
        bands, windows = route_volumes(schedule, start, len(path) - 1, resolution, since, tolerance)
        return PathRoute(tuple(points), bands, windows)

    async def _answer(self, peer: int, session: int) -> None:
        """Answer a run request -- only once it has shown who asks (a trusted certificate, a
        signature, a fresh time, not a replay) and that the run is plausible and within the
        budget: nobody else makes us work, and what goes back is a one-byte abort code or a
        signed refusal, never anything about our path."""
        setups = self.chooser_setups.setdefault(peer, {})
        self._answering += 1
        waiting = False
        try:
            request = await self.endpoint.receive(peer, session)
            admitted = await self._admit(peer, session, request)
            if admitted is None:
                return
            responder, hello, ticket = admitted
            self._answers_waiting += 1
            waiting = True
            async with self._radio.turn(ANSWER_NEAR if hello.horizon_m > 0 else ANSWER_FULL):
                self._answers_waiting, waiting = self._answers_waiting - 1, False
                self._sessions += 1
                separation = run_volumes(
                    self.settings.separation, hello.grid.resolution_mm, 0
                ).separation
                bob = Bob(
                    self._bob_path,
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
                            timeout=self.settings.run_timeout_s,
                            first=responder.init.hello,
                            alive=functools.partial(self._still_heard, peer),
                        )
                finally:
                    self._sessions -= 1
                    if not responder.keyed:  # no first reply: Alice learnt nothing
                        self.ledger.refund(ticket)
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
            if waiting:
                self._answers_waiting -= 1
            self._answering -= 1
            self._wake.set()
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

    async def _admit(
        self, peer: int, session: int, request: bytes
    ) -> tuple[Responder, Hello, int] | None:
        """The checks before any work on a request, cheapest first.  None: the request was
        dropped, aborted (code only) or refused (signed), and the session is closed."""
        wall = self.clock.wall()
        skew = self.settings.max_clock_skew_s
        try:
            init = Init.parse(request)
        except AuthenticationError as exc:
            self.endpoint.abort(peer, session, AbortCode.AUTH)
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, auth=str(exc)))
            return None
        responder = Responder(self.identity, init, Route(peer, self.settings.node, session))
        neighbour = self.neighbours.get(peer)
        known = self.peers.get(peer)
        if neighbour is None or known is None or known.identity != neighbour.fingerprint:
            if self.neighbours.untrusted(peer):  # ignored: not a word back
                self.endpoint.close_session(peer, session)
                return None
            # A drone whose certificate (or beacon) we lack: say so -- signed, at most every
            # half a beacon interval -- and ask for its certificate.
            self.sender.send_certificate(ask=True)
            if self.clock.now() - self._unknown_refused >= self.cadence.asked_every_s:
                self._unknown_refused = self.clock.now()
                await self._refuse(peer, session, responder, Refusal.UNKNOWN_PEER)
            else:
                self.endpoint.close_session(peer, session)
            return None
        # Fresh: made when its first frame could have left (a duty-cycled sender may wait
        # up to a window for its budget); answered once (the replay cache on disk outlives
        # the window).
        wait = self.endpoint.profile.budget_wait_s
        try:
            responder.verify(neighbour.cert, self.endpoint.arrived(peer, session), skew, wait)
            forget = wall - 2 * (skew + wait)
            if not self.store.first_request(init.replay_key, wall, forget):
                raise AuthenticationError("a request answered before (a replay)")
        except AuthenticationError as exc:
            # Signed: the requester's link takes no abort without a proof (a stale request
            # of an honest drone learns at once; a forger's learns nothing new).
            proof = responder.abort_proof(AbortCode.AUTH)
            self.endpoint.abort(peer, session, AbortCode.AUTH, proof)
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, auth=str(exc)))
            return None
        try:
            hello = Hello.from_bytes(init.hello)
        except ProtocolError as exc:
            proof = responder.abort_proof(AbortCode.PROTOCOL)
            self.endpoint.abort(peer, session, AbortCode.PROTOCOL, proof)
            self.record(EventKind.ANSWER_FAILED, PeerFailure(peer=peer, error=str(exc)))
            return None
        operator = neighbour.operator
        code = self._refusal(peer, hello, known, operator.max_segments)
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

    def _refusal(self, peer: int, hello: Hello, known: Peer, max_segments: int) -> Refusal | None:
        """The checks on an authenticated request before any work, cheapest first: the role,
        a radio that is not free, the size (its beacon's, its operator's limit, a fair run's
        work) and the box; the refusal, or None to go on."""
        if known.role is Role.ALICE:
            if self.settings.node < peer:
                # Both took the pair as Alice (their views of who was on the ground crossed):
                # exactly one of a pair adjusts -- the lower node id keeps the role.
                return Refusal.ROLE
            self.record(
                EventKind.YIELDED, PeerNote(peer=peer, reason="the peer has the lower node id")
            )
        own = self._own_on_air
        if (own is not None and own.n is None) or self._answers_waiting:
            # Our own run holds the radio and still waits for its peer's first reply (a
            # third drone, perhaps busy itself), or another answer already waits for the
            # radio: a request kept waiting would keep its sender's radio idle too, a chain
            # of drones each waiting on the next (companion.runs.turns).  Otherwise it waits: at
            # most one answer behind a run that is under way.
            return Refusal.BUSY
        allowed = min(max_segments, 1 << min(known.beacon.size_class, MAX_SIZE_CLASS))
        if hello.m > allowed:  # more than its beacon announced or its operator allows
            return Refusal.SIZE
        if run_work(hello.m, self._own_size(), hello.grid.range) > MAX_RUN_WORK:
            # More than a fair run (m x n x grid bits): Bob's CPU, memory and first reply
            # grow with it, and a refused run costs the asker nothing.
            return Refusal.SIZE
        if not self._plausible_box(hello, known):
            return Refusal.BOX
        return None

    def _plausible_box(self, hello: Hello, known: Peer) -> bool:
        """Alice's grid is centred where she is (her position when the run starts): within
        what she can have flown since the last position her track of verified beacons makes
        plausible (:attr:`Peer.anchor`: a beacon that jumps faster than ``MAX_SPEED_M_S``
        moves no box), and within ``max_peer_range_m`` of us (a drone on our radio); it
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
        return distance_m(centre, known.anchor[1]) <= known.reach_m(self.clock.now())

    async def _refuse(self, peer: int, session: int, responder: Responder, code: Refusal) -> None:
        self.record(EventKind.REFUSED, PeerNote(peer=peer, reason=code.name))
        try:
            await self.endpoint.send(peer, session, responder.refuse(code))
        except LinkError:
            pass
        finally:
            self.endpoint.close_session(peer, session)
