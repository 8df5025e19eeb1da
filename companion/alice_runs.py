"""Alice's side: which peer to compare with next, and one run with it.

Near runs (what both can reach soon) before full runs, the most urgent peer first, one run on
the radio at a time; each run is the protocol of :mod:`protocol.intersection` over the link
(:func:`companion.exchange.run_alice`), watched by the fail-safe while it lasts, and its flags
become conflicts that the edits turn into altitude levels.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import logging
import math

from protocol.compact_plan import message_sizes
from protocol.errors import ConsistencyError, ProtocolError
from protocol.grid import GridSpec
from protocol.intersection import MAX_SEGMENTS, Alice, Limits
from protocol.wire import Suite

from .auth.certificate import Certificate
from .auth.session import AuthenticationError, Initiator, Refusal, Route
from .beacon import keys_hash
from .budget import ALICE, BudgetExceeded
from .edits import Edits
from .events import EventKind
from .exchange import PeerRefused, run_alice
from .failsafe import too_late
from .link.arq import LinkError
from .neighbours import Neighbour
from .peers import Peer, distance_m, time_to_meet
from .progress import RunProgress
from .radio import OWN_FULL, OWN_NEAR
from .roles import Role

log = logging.getLogger("companion")
NEAR_SLACK_S = 30.0  # the near run reaches this far past the earliest possible meeting
BOB_GUESS = 4  # Bob's size before he tells it: a remaining route of a few legs (m x m would
# stretch the horizon of a long route over everything; the run watch uses his real size)
QUIET_S = 5.0  # no session traffic heard this long: the channel is free for a full run
GROUND_WAIT_S = 60.0  # on the ground, a run waits this long at most for a quiet channel


class AliceRuns(Edits):
    """Comparing as Alice."""

    async def _alice_loop(self) -> None:
        """One run at a time: every pending near run before any full run, the most urgent
        peer first; no new run while we answer a peer (one radio, half duplex)."""
        while True:
            with contextlib.suppress(TimeoutError):
                await self.clock.wait_for(self._wake.wait(), 1.0)
            self._wake.clear()
            now = self.clock.now()
            due = [p for p in self.peers.values() if self._should_compare(p, now)]
            if not due:
                continue
            for peer in due:
                version = (peer.beacon.mission_version, self.version)
                if peer.plan_version != version or not peer.plan:
                    if peer.plan_version != version:
                        peer.covered = set()
                    peer.plan, peer.plan_version = self._phases(peer), version
            # A full run after a near run waits until it is needed (or the channel is quiet):
            # meanwhile the radio serves every drone's near runs.
            quiet = not self.endpoint.busy(QUIET_S) and not self._radio.waiting()
            if self.on_ground and not quiet:
                # Before take-off nothing is urgent, and a run started while other drones'
                # run is on the air slows theirs (in flight, perhaps past their deadline):
                # wait for a quiet channel, a minute at most.
                if self._ground_wait is None:
                    self._ground_wait = now
                if now - self._ground_wait < GROUND_WAIT_S:
                    continue
            self._ground_wait = None
            ready = [p for p in due if p.plan[0][0] == "near" or p.full_after <= now or quiet]
            if not ready:
                continue
            peer = min(ready, key=lambda p: (p.plan[0][0] != "near", self._urgency(p)))
            phase, horizon = peer.plan[0]
            try:
                priority = OWN_NEAR if phase == "near" else OWN_FULL
                async with self._busy, self._radio.turn(priority):
                    done = await self._run(peer, phase, horizon)
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # nothing may stop the companion
                log.exception("node %d: comparison failed", self.settings.node)
                self.record(EventKind.RUN_FAILED, peer=peer.node, error=f"internal: {exc!r}")
                done = False
            if done:
                peer.plan.pop(0)
                if not peer.plan:
                    peer.compared = peer.plan_version
                elif phase == "near":
                    peer.full_after = self._full_deadline(peer, horizon)
            else:
                peer.plan = []
                peer.next_try = self.clock.now() + self.settings.retry_after_s
            self._wake.set()  # look again at once

    def _full_deadline(self, peer: Peer, horizon: int) -> float:
        """When the full run must start at the latest: before we leave what the near run
        compared, and before the peer can be beyond what it showed (its horizon), less the
        run's estimated time and the margin.  On the ground: at once."""
        now = self.clock.now()
        if self.on_ground:
            return now
        speed = max(self.speed_m_s, self.settings.cruise_m_s)
        start, path = self._remaining_path()
        covered = [k - start for k in sorted(peer.covered) if k >= start]
        here = self._here()
        left = sum(
            distance_m(here if here is not None and k == 0 else a, b)
            for k, (a, b) in enumerate(itertools.pairwise(path))
            if k <= (covered[-1] if covered else -1)
        )
        grid = self._grid(path)
        m = Limits().padded(min(max(len(path) - 1, 1), MAX_SEGMENTS))
        slack = min(left, horizon) / speed - self._seconds(m, grid, fresh=False)
        return now + max(slack - self.settings.failsafe.margin_s, 0.0)

    def _phases(self, peer: Peer) -> list[tuple[str, int]]:
        """The runs a comparison with ``peer`` takes: near (what can be reached soon) when the
        remaining path reaches beyond its horizon, then full (horizon 0: everything)."""
        _, path = self._remaining_path()
        phases = [("full", 0)]
        if self.settings.lookahead_s > 0 and len(path) >= 2:
            horizon = self._horizon_m(peer, path)
            if len(self._near(path, horizon)) < len(path):
                phases.insert(0, ("near", horizon))
        return phases

    def _horizon_m(self, peer: Peer, path: list[tuple[int, int]]) -> int:
        """How far ahead the near run looks: long enough that what lies beyond can wait for
        the full run -- every peer now due gets its near and its full run, one at a time, so
        the estimate counts them all --, past the worst-case time until the peer could be
        here (a near run that ends before that moment would find nothing), and at least
        lookahead_s of flight.  Every term comes from what the beacons and the run sizes
        already tell: the horizon shows Bob nothing about Alice's path."""
        speed = max(self.speed_m_s, self.settings.cruise_m_s)  # Bob cuts his path alike
        grid = self._grid(path)
        m = Limits().padded(min(len(path) - 1, MAX_SEGMENTS))
        now = self.clock.now()
        due = [p for p in self.peers.values() if self._should_compare(p, now)] or [peer]
        runs = sum(
            self._seconds(2, grid, fresh=p.node not in self.holder_setups)
            + self._seconds(m, grid, fresh=False, n=min(m, BOB_GUESS))
            for p in due
        )
        # Nothing can happen before the peer could be here (both at cruise speed at least);
        # reach well past that moment.
        cruise = self.settings.cruise_m_s
        meet = time_to_meet(self.position[:2], speed, peer, floor_m_s=cruise, measured=False)
        meet += NEAR_SLACK_S
        meet = meet if math.isfinite(meet) else 0.0
        seconds = max(self.settings.lookahead_s, runs + self.settings.failsafe.margin_s, meet)
        return round(seconds * speed)

    async def _run(self, peer: Peer, phase: str, horizon: int) -> bool:
        """One run; True when it ended with a result (or had nothing to compare)."""
        start, path = self._remaining_path()
        path = self._near(path, horizon)
        if len(path) < 2:
            return True
        neighbour = self.neighbours.get(peer.node)
        if neighbour is None or neighbour.fingerprint != peer.identity:
            self._forget(peer.node)  # its certificate is gone or taken over: not our peer
            return False
        op = neighbour.operator
        if self.settings.suite is Suite.PAPER and not op.paper_keys:
            # Bob's unproven keys could make what he decrypts depend on our path: only with
            # drones whose operator vouches for them (trust.operator.paper_keys).
            error = f"operator {op.name} is not trusted with paper-suite keys (paper_keys)"
            self.record(EventKind.RUN_FAILED, peer=peer.node, phase=phase, error=error)
            return False
        try:
            ticket = self.ledger.admit(
                peer.identity, op.key.fingerprint, op.max_runs_per_hour, self.clock.wall(), ALICE
            )
        except BudgetExceeded as exc:
            self.record(EventKind.BUDGET, peer=peer.node, error=str(exc))
            return False
        done = await self._compare(peer, phase, horizon, start, path, neighbour)
        if not done:
            self.ledger.refund(ticket)  # no result: a retry must not use up our runs
        return done

    async def _compare(
        self,
        peer: Peer,
        phase: str,
        horizon: int,
        start: int,
        path: list[tuple[int, int]],
        neighbour: Neighbour,
    ) -> bool:
        """The run itself (a fresh OT setup again if the peer lost ours)."""
        peer.role = Role.ALICE
        for attempt in range(2):
            grid = self._grid(path)
            setup = self.holder_setups.get(peer.node)
            try:
                alice = Alice(
                    grid.project_path(path),
                    grid,
                    suite=self.settings.suite,
                    setup=setup,
                    horizon_m=horizon,
                    ot_security=self.settings.ot_security,
                    trusted_keys=neighbour.operator.paper_keys,
                )
            except ProtocolError as exc:
                self.record(EventKind.RUN_FAILED, peer=peer.node, phase=phase, error=str(exc))
                return False
            # Bob's size is unknown until his first reply: act at once only if even the
            # smallest Bob makes the result too late; the watch re-checks with his real size.
            needed = self._seconds(alice.m, grid, fresh=setup is None, n=1)
            meet = self._urgency(peer)
            self.record(
                EventKind.RUN_STARTED,
                peer=peer.node,
                phase=phase,
                segments=alice.m,
                first_segment=start,
                estimate_s=round(needed, 1),
                time_to_meet_s=round(meet, 1) if math.isfinite(meet) else None,
            )
            if too_late(needed, meet, self.settings.failsafe):
                await self._precaution(peer, needed, meet)
            watchdog = asyncio.create_task(self._watch(peer, alice, grid, needed))
            self._sessions += 1

            def secure(session: int, cert: Certificate = neighbour.cert) -> Initiator:
                route = Route(self.settings.node, peer.node, session)
                return Initiator(self.identity, cert, route, self.clock.wall())

            progress = RunProgress(
                self.settings.node,
                self.endpoint,
                peer.node,
                Role.ALICE,
                expected_bytes=functools.partial(self._run_bytes, alice, grid, fresh=setup is None),
                ends_at=lambda: None if self._running is None else self._running[1],
            )
            try:
                with progress:
                    report = await run_alice(
                        self.endpoint,
                        peer.node,
                        alice,
                        secure=secure,
                        check_keys=lambda boot, public: (
                            neighbour.beacon_key is not None
                            and keys_hash(boot, neighbour.beacon_key, public) == neighbour.keys_hash
                        ),
                        timeout=self.settings.run_timeout_s,
                    )
            except PeerRefused as exc:
                if exc.code is Refusal.UNKNOWN_SETUP and attempt == 0:
                    self.holder_setups.pop(peer.node, None)  # the peer lost it: start afresh
                    self.record(EventKind.SETUP_RENEWED, peer=peer.node)
                    continue
                if exc.code is Refusal.ROLE:
                    peer.role = Role.BOB  # the peer already resolved this pair as Alice
                    self.record(EventKind.YIELDED, peer=peer.node, reason="the peer is Alice")
                    return False
                if exc.code is Refusal.UNKNOWN_PEER:
                    self._cert_now.set()  # it lacks our certificate: beacon it
                box = (  # off our beacons, or beyond the peer's limits: which box we asked
                    {"box_radius_m": grid.radius_m, "resolution_mm": grid.resolution_mm}
                    if exc.code is Refusal.BOX
                    else {}
                )
                self.record(
                    EventKind.RUN_FAILED,
                    peer=peer.node,
                    phase=phase,
                    refused=exc.code.name,
                    **box,
                )
                return False
            except AuthenticationError as exc:
                self.record(EventKind.RUN_FAILED, peer=peer.node, phase=phase, auth=str(exc))
                return False
            except ConsistencyError as exc:
                # The peer's OT extension is not the honest one: it probed our Delta.  Drop
                # the setup (a wrong guess must not be followed by another on the same Delta).
                self.holder_setups.pop(peer.node, None)
                self.record(EventKind.RUN_FAILED, peer=peer.node, phase=phase, deviated=str(exc))
                return False
            except (ProtocolError, LinkError, ValueError) as exc:
                self.record(EventKind.RUN_FAILED, peer=peer.node, phase=phase, error=str(exc))
                return False
            finally:
                self._sessions -= 1
                self._running = None
                watchdog.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await watchdog
            break
        else:
            return False
        if alice.setup is not None:
            self.holder_setups[peer.node] = alice.setup
        flagged = {start + j for j, hit in enumerate(report.hits) if hit}
        covered = set(range(start, start + len(path) - 1))
        peer.conflicts = (peer.conflicts - covered) | flagged
        peer.covered |= covered
        self.record(
            EventKind.RESULT,
            peer=peer.node,
            phase=phase,
            hits=report.hits,
            first_segment=start,
            flagged=sorted(flagged),
            bytes=report.bytes_sent,
            auth_bytes=report.auth_bytes_sent,
            cpu_s=round(report.cpu_s, 3),
            run_s=round(report.wall_s, 1),
        )
        if phase == "full" or covered >= self.precaution.get(peer.node, set()):
            await self._release(peer)
        await self._replan(f"result of the {phase} run with {peer.node}")
        return True

    def _run_bytes(self, alice: Alice, grid: GridSpec, *, fresh: bool) -> int | None:
        """Payload bytes the run is expected to move both ways (Bob's size guessed as
        Alice's until his first reply; None for the paper suite, which has no size model)."""
        if self.settings.suite is not Suite.COMPACT:
            return None
        n = alice.m if alice.n is None else alice.n
        sizes = message_sizes(
            alice.m, n, grid, fresh_setup=fresh, ot_security=self.settings.ot_security
        )
        return sum(size for _, size in sizes)
