"""The fail-safe at work: no result may come too late.

While a run of ours is under way, :meth:`Guard.watch` re-estimates when its result comes;
for every other peer still waiting for its run, :meth:`Guard.guard` asks whether even the
smallest run, started once ours ends, would come in time.  When not, :meth:`Guard.precaution`
picks the segments both drones may reach before the result
(:func:`companion.runs.failsafe.at_risk`) and :class:`companion.runs.edits.Edits` climbs
over them or holds before them until the result is in.
"""

from __future__ import annotations

import math

from companion.context import Context
from companion.events import EventKind, Precaution
from companion.mission.own_flight import OwnFlight
from companion.neighbours.neighbourhood import Neighbourhood
from companion.neighbours.peers import Peer
from companion.radio.endpoint import LinkEndpoint
from companion.runs.edits import Edits
from companion.runs.estimates import RunEstimates
from companion.runs.failsafe import Action, act_now, at_risk, too_late
from companion.runs.standing import Standing
from protocol.geo.grid import GridSpec
from protocol.intersection import Alice
from protocol.run import DEFAULT_LIMITS

CHECK_EVERY_S = 2.0  # how often the watch and the guard look again


class Guard:
    def __init__(
        self,
        ctx: Context,
        endpoint: LinkEndpoint,
        flight: OwnFlight,
        neighbourhood: Neighbourhood,
        standing: Standing,
        edits: Edits,
        estimates: RunEstimates,
    ) -> None:
        self.ctx = ctx
        self.settings = ctx.settings
        self.endpoint = endpoint
        self.flight = flight
        self.vehicle = flight.vehicle
        self.neighbourhood = neighbourhood
        self.standing = standing
        self.edits = edits
        self.estimates = estimates
        self.running: tuple[int, float] | None = None  # our run's peer, its expected end

    def ends_at(self) -> float | None:
        """When our run under way should end (None: none is)."""
        return None if self.running is None else self.running[1]

    async def watch(self, peer: Peer, alice: Alice, grid: GridSpec, needed: float) -> None:
        """While a run is under way: act as soon as its result could come too late.  Until
        Bob's first reply tells his size the estimate is that of the smallest Bob (Alice's
        own size would cry wolf when Bob's path is short: runs are sized m x n); then it is
        the rest of the real m x n run from that moment; past it, as long as the overrun.
        A wait for our duty-cycle budget counts when even a lossless run could not escape it,
        or when it comes (a frame is queued for the budget): a run whose share fits the
        budget only if few frames are lost is watched, not given up at once -- the margin
        still leaves time to act when the wait comes.  The run clears :attr:`running` when
        it ends."""
        clock = self.ctx.clock
        deadline = clock.now() + needed
        self.running = (peer.node, deadline)
        sized = False
        while True:
            await clock.sleep(CHECK_EVERY_S)
            if not sized and alice.n is not None:
                sized = True  # messages 1 and 2 (hello, offer) are behind us
                rest = self.estimates.seconds(
                    alice.m, grid, fresh=False, n=alice.n, skip=2, stall_loss=0.0
                )
                deadline = clock.now() + rest
                self.running = (peer.node, deadline)
            # Overdue (losses, a silent peer): the estimate has failed; expect as long again
            # as it has overrun, so the fail-safe does not wait for the last seconds.
            left = max(abs(deadline - clock.now()), 2.0) + self.endpoint.budget_wait()
            meet = self.neighbourhood.urgency(peer)
            if act_now(left, meet, self.neighbourhood.earliest(peer), self.settings.failsafe):
                await self.precaution(peer, left, meet)
                return

    async def guard(self) -> None:
        """The fail-safe for peers still waiting for their run (one run at a time on the
        radio, a retry after a failure): act when even the smallest run, started once ours
        on the air ends, would bring the result too late.  The peer a run is under way with
        has its own watch."""
        while True:
            await self.ctx.clock.sleep(CHECK_EVERY_S)
            if self.vehicle.on_ground or not self.neighbourhood.peers:
                continue
            now = self.ctx.clock.now()
            running, ends = self.running or (None, now)
            for peer in list(self.neighbourhood.peers.values()):
                if (
                    peer.node == running
                    or peer.node in self.edits.precaution
                    or not self.standing.pending(peer)
                ):
                    continue
                smallest = self.smallest_run_s(peer)
                if smallest is None:
                    break
                needed = max(ends - now, 0.0) + smallest
                meet = self.neighbourhood.urgency(peer)
                earliest = self.neighbourhood.earliest(peer)
                if act_now(needed, meet, earliest, self.settings.failsafe):
                    await self.precaution(peer, needed, meet, waiting=True)

    def smallest_run_s(self, peer: Peer) -> float | None:
        """Link seconds the smallest run with ``peer`` would need, started now (None: no
        path left to compare)."""
        _, path = self.flight.remaining_path()
        if len(path) < 2:
            return None
        first = self.flight.near(path, 1)  # the least a run compares
        return self.estimates.seconds(
            DEFAULT_LIMITS.public_size(len(first) - 1),
            self.flight.grid(first),
            fresh=peer.node not in self.neighbourhood.holder_setups,
            n=1,
        )

    def pressing(self, peer: Peer, slack_s: float) -> bool:
        """A run with ``peer`` that starts ``slack_s`` from now would come too late."""
        smallest = self.smallest_run_s(peer)
        if smallest is None:
            return False
        meet = self.neighbourhood.urgency(peer)
        return too_late(smallest + slack_s, meet, self.settings.failsafe)

    async def precaution(
        self, peer: Peer, needed: float, meet: float, *, waiting: bool = False
    ) -> None:
        """Climb over (or hold before) the segments both drones may reach before the result.
        The path is what is left to fly *now*: a run's path starts where the drone was when
        it began, and distances from here along legs already flown would come out wrong."""
        settings = self.settings.failsafe
        if self.edits.covers(peer.node) or self.vehicle.on_ground:
            return  # (on the ground the drone waits for its comparisons anyway)
        start, path = self.flight.remaining_path()
        speed = max(self.vehicle.speed_m_s, self.settings.cruise_m_s)
        schedule = self.flight.original_schedule(start)
        tolerance = self.settings.separation.tolerance
        windows = [schedule.window(k, tolerance) for k in range(start, start + len(path) - 1)]
        # A segment a run found in conflict with this peer and that we fly raised for it
        # (verified upload) needs no precaution while it is compared again (the peer or we
        # were retimed: the comparison restarts, the raise stands until its result).
        raised = {k for k in peer.conflicts if self.flight.raises.get(k)}
        decided = self.standing.decided(peer) | raised
        risky = at_risk(
            path, start, self.vehicle.here(), speed, peer.position,
            self.neighbourhood.peer_speed(peer), needed, settings, decided,
            peer_age_s=peer.position_age(self.ctx.clock.now()),
            entered=[w[0] for w in windows],
            # A hold stops at the start of the first segment at risk, the end of the one
            # before: that one is not left before the peer comes, whatever the schedule says.
            left=None if settings.action is Action.HOLD else [w[1] for w in windows],
        )  # fmt: skip
        if not risky:
            return
        self.ctx.record(
            EventKind.PRECAUTIONARY,
            Precaution(
                peer=peer.node,
                action=settings.action.value,
                segments=risky,
                first_segment=start,
                needed_s=round(needed, 1),
                time_to_meet_s=round(meet, 1) if math.isfinite(meet) else None,
                waiting=waiting,
            ),
        )
        await self.edits.take(peer.node, settings.action, risky)
