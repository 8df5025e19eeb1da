"""Alice's side: which peer to compare with next, and one run with it.

Near runs (what both can reach soon) before full runs, the most urgent peer first, one run on
the radio at a time; each run is the protocol of :mod:`protocol.intersection` over the link
(:func:`companion.runs.exchange.run_alice`), watched by the fail-safe while it lasts, and its flags
become conflicts that the edits turn into altitude levels.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
import secrets

from companion.auth.certificate import Certificate
from companion.auth.session import AuthenticationError, Identity, Initiator, Refusal, Route
from companion.context import Context
from companion.errors import CompanionError
from companion.events import EventKind, PeerFailure, PeerNote, RunResult, RunStarted
from companion.mission.ground import COVER_ALL, along_m, near_cut, segment_distance_m
from companion.mission.own_flight import OwnFlight
from companion.mission.schedule import route_volumes
from companion.neighbours.beacon import keys_hash
from companion.neighbours.neighbourhood import Neighbourhood
from companion.neighbours.peers import Peer, time_to_meet
from companion.neighbours.registry import Neighbour
from companion.radio.arq import PeerElsewhere
from companion.radio.endpoint import LinkEndpoint
from companion.roles import Phase, Role
from companion.runs.budget import ALICE, MAX_RUN_WORK, BudgetExceeded, RunLedger, run_work
from companion.runs.edits import Edits
from companion.runs.estimates import RunEstimates
from companion.runs.exchange import PeerRefused, RunReport, run_alice
from companion.runs.failsafe import act_now, too_late
from companion.runs.guard import Guard
from companion.runs.progress import RunProgress
from companion.runs.standing import Standing
from companion.runs.turns import OWN_FULL, OWN_NEAR, Air
from protocol.errors import ConsistencyError, ProtocolError
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import CROSSING, VolumeSpec
from protocol.geo.volumes import Route as PathRoute
from protocol.intersection import Alice
from protocol.messages import Suite
from protocol.ot.setup import HolderSetup
from protocol.run import DEFAULT_LIMITS, MAX_SEGMENTS

log = logging.getLogger("companion")
NEAR_SLACK_S = 30.0  # the near run reaches this far past the earliest possible meeting
NEAR_SLACK = 1.1  # a first run takes this much longer than its estimate (measured on US915
# SF7 at 10 % loss: 35-41 s against 36.5 s with a fresh OT setup, the setup's computing)
BOB_GUESS = 4  # Bob's size before he tells it: a remaining route of a few legs (m x m would
# stretch the horizon of a long route over everything; the run watch uses his real size)
QUIET_S = 5.0  # no session traffic heard this long: the channel is free for a full run
GROUND_WAIT_S = 60.0  # on the ground, a run waits this long at most for a quiet channel
IDLE_BEACONS = 2.0  # several channels: a peer heard within this many beacon intervals is idle
QUIET_CYCLES = (2.0, 6.0)  # in flight on one channel, a new run waits for a random quiet of
# this many frame-ACK cycles after other pairs' run traffic (about 1-3 s on SF7)
LOAD_WINDOW_S = 5.0  # ... and once the channel carried frames less than LOAD_MAX of the last
LOAD_MAX = 0.5  # LOAD_WINDOW_S (a beacon storm: a run's first frame waits behind it)
NEAR_ASK = 4  # a near run asks for four of the peer's segments when that still comes in time
LAZY_RUNS = 9.0  # a crowded sky (more pairs in range than this): a peer that could not be
# here within the time of this many first runs waits (the fail-safe's own measure,
# :meth:`Neighbourhood.urgency`; 368 s on US915 SF7)
MEASURE_WAIT = 2.5  # ... a peer first heard waits this many beacon intervals to be measured
PRESS_S = 20.0  # ... unless a run with its peer started this much later would come too late
ENGAGED_DEFER_S = 60.0  # a peer heard in other pairs' runs is asked anyway after this long:
# frame headers are anybody's to forge, and a stranger must not keep our runs off for good


class AliceRuns:
    """Comparing as Alice: :meth:`loop` runs the comparisons; :attr:`comparing` says whether
    one is under way or due."""

    def __init__(
        self,
        ctx: Context,
        endpoint: LinkEndpoint,
        identity: Identity,
        flight: OwnFlight,
        neighbourhood: Neighbourhood,
        standing: Standing,
        edits: Edits,
        guard: Guard,
        estimates: RunEstimates,
        air: Air,
        ledger: RunLedger,
    ) -> None:
        self.ctx = ctx
        self.settings = ctx.settings
        self.clock = ctx.clock
        self.record = ctx.record
        self.endpoint = endpoint
        self.identity = identity
        self.flight = flight
        self.vehicle = flight.vehicle
        self.neighbourhood = neighbourhood
        self.sender = neighbourhood.sender
        self.standing = standing
        self.edits = edits
        self.guard = guard
        self.estimates = estimates
        self.air = air
        self.ledger = ledger
        self._busy = asyncio.Lock()  # a comparison of ours is under way
        self._deferred: dict[int, float] = {}  # peer -> since when it is heard in other runs
        self._quiet_need: float | None = None  # the quiet our next run waits for (drawn)
        self._wake = asyncio.Event()
        self._ground_wait: float | None = None  # since when a run waits for a quiet channel

    def wake(self) -> None:
        """Look at the peers again at once (one was heard, an answer ended)."""
        self._wake.set()

    @property
    def comparing(self) -> bool:
        """A comparison as Alice is under way, half done, or put off by a peer busy with its
        own (a drone about to take off waits for it); not one half done with a peer that has
        since gone out of range or fallen silent: it resumes if they meet again."""
        now = self.clock.now()
        hood = self.neighbourhood
        return self._busy.locked() or any(
            (p.plan or p.busy or hood.introducing(p, now))
            and self.standing.pending(p)
            and not hood.silent_for(p)
            for p in hood.peers.values()
        )

    async def loop(self) -> None:
        """One run at a time: every pending near run before any full run, the most urgent
        peer first; no new run while we answer a peer (one radio, half duplex)."""
        while True:
            with contextlib.suppress(TimeoutError):
                await self.clock.wait_for(self._wake.wait(), 1.0)
            self._wake.clear()
            peer = self._next(self.clock.now())
            if peer is None:
                continue
            phase, horizon = peer.plan[0]
            done = await self._turn(peer, phase, horizon)
            self._after(peer, phase, horizon, done=done)
            self._wake.set()  # look again at once

    def _next(self, now: float) -> Peer | None:
        """The peer whose run goes next (its plan made or renewed), or None for now."""
        due = [p for p in self.neighbourhood.peers.values() if self.standing.due(p, now)]
        if not due:
            return None
        for peer in due:
            version = self.standing.versions(peer)
            if peer.plan_version != version or not peer.plan:
                if peer.plan_version != version:
                    peer.covered, peer.settled, peer.near_run = set(), set(), None
                peer.plan, peer.plan_version = self._phases(peer), version
                peer.recheck_at = math.inf
        # A full run after a near run waits until it is needed (or the channel is quiet):
        # meanwhile the radio serves every drone's near runs.
        quiet = not self.endpoint.busy(QUIET_S) and not self.air.turns.waiting()
        # (its deferrals counted from now on, alongside the ground's wait: they do not add up)
        engaged = {p.node for p in due if self._engaged(p, now)}
        if self.vehicle.on_ground and not quiet:
            # Before take-off nothing is urgent, and a run started while other drones'
            # run is on the air slows theirs (in flight, perhaps past their deadline):
            # wait for a quiet channel, a minute at most.
            if self._ground_wait is None:
                self._ground_wait = now
            if now - self._ground_wait < GROUND_WAIT_S:
                return None
        self._ground_wait = None
        lazy = self._lazy_s()
        ready = [
            p
            for p in due
            if (p.plan[0][0] is Phase.NEAR or p.full_after <= now or quiet)
            and p.node not in engaged
            and (lazy is None or self._urgent(p, now, lazy))
        ]
        if not ready:
            return None
        urgency = self.neighbourhood.urgency
        if not self._channel_ours(min(ready, key=urgency)):
            return None
        # Several channels: a peer in a run elsewhere does not hear us (nor beacons): one
        # heard lately on the common channel goes first
        lately = now - IDLE_BEACONS * self.settings.beacon_interval_s
        channels = self.endpoint.channels > 1
        return min(
            ready,
            key=lambda p: (
                p.plan[0][0] is not Phase.NEAR,
                channels and p.heard_at < lately,
                urgency(p),
            ),
        )

    def _lazy_s(self) -> float | None:
        """How soon a peer must be able to be here to be compared now, in a crowded sky --
        in flight, more than :data:`LAZY_RUNS` pairs of drones in range: that many first runs
        (two segments each with a fresh OT setup) -- else None: compare every peer once heard.
        Comparing everyone at once fills a crowded channel with pairs that never come near
        -- busy_ten's parallel tracks 800 m apart were most of its runs -- while the pairs
        that do wait behind them (their fail-safe climbs).  From the neighbourhood's size
        and the run sizes only; in first runs, so a slow link (EU868 SF9's duty cycle: 40
        minutes a run) waits as long in runs as a fast one."""
        if self.vehicle.on_ground:
            return None  # (before take-off every peer is compared: the ground waits)
        _, path = self.flight.remaining_path()
        drones = len(self.neighbourhood.peers) + 1
        if len(path) < 2 or drones * (drones - 1) / 2 <= LAZY_RUNS:
            return None
        return LAZY_RUNS * self.estimates.seconds(2, self.flight.grid(path), fresh=True)

    def _urgent(self, peer: Peer, now: float, lazy_s: float) -> bool:
        """Whether a crowded sky compares with ``peer`` now: when it could be here within
        ``lazy_s`` by the fail-safe's measure (a range rate from two beacons, fresh, else
        flying straight at us), and a peer met moments ago, not measured yet, only when a
        run with it could not wait for its second beacon (:meth:`Guard.pressing`)."""
        interval = self.neighbourhood.cadence.interval_s
        if not peer.measured and now - peer.met_at < MEASURE_WAIT * interval:
            return self.guard.pressing(peer, PRESS_S)
        return self.neighbourhood.urgency(peer) <= lazy_s

    def _channel_ours(self, peer: Peer) -> bool:
        """In flight on one channel, a run starts once other pairs' runs have left the
        channel quiet for a random few frame cycles, and once the channel (beacons too) is
        no longer loaded (:data:`LOAD_MAX`): runs started together share its airtime and
        collide, and all come late; one at a time each is as quick as alone, and the random
        wait keeps the drones that waited from all starting together again.  The load
        matters at the start of a busy sky, when no run is on the air yet to defer to while
        the drones' introductions fill the channel (busy_ten: nine runs began within 20 s,
        their first frames waited 19-54 s behind the beacons, the first result came at
        260 s).  A run with ``peer`` that would come too late if it waited longer
        (:data:`PRESS_S`) does not wait."""
        if self.endpoint.channels > 1 or self.vehicle.on_ground:
            return True  # (on the ground: the quiet channel of _next)
        if self._quiet_need is None:
            low, high = QUIET_CYCLES
            draw = low + (high - low) * secrets.randbelow(1 << 16) / (1 << 16)
            self._quiet_need = draw * self.endpoint.cycle_s
        taken = (
            self.endpoint.others_quiet_s() < self._quiet_need
            or self.endpoint.load(LOAD_WINDOW_S) >= LOAD_MAX
        )
        if taken and not self.guard.pressing(peer, PRESS_S):
            return False
        self._quiet_need = None
        return True

    def _engaged(self, peer: Peer, now: float) -> bool:
        """The peer is in another pair's run on the air: a request now would be refused BUSY
        (or go unheard) after its whole hello -- in a busy sky most requests were (busy_ten:
        47 of 55).  Deferred to for :data:`ENGAGED_DEFER_S` at most."""
        if not self.endpoint.engaged(peer.node):
            self._deferred.pop(peer.node, None)
            return False
        return now - self._deferred.setdefault(peer.node, now) < ENGAGED_DEFER_S

    async def _turn(self, peer: Peer, phase: Phase, horizon: int) -> bool:
        """The run, once the radio is ours; a bug in it is recorded, never fatal."""
        try:
            priority = OWN_NEAR if phase is Phase.NEAR else OWN_FULL
            async with self._busy, self.air.turns.turn(priority):
                return await self._run(peer, phase, horizon)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # nothing may stop the companion
            log.exception("node %d: comparison failed", self.settings.node)
            failure = PeerFailure(peer=peer.node, error=f"internal: {exc!r}")
            self.record(EventKind.RUN_FAILED, failure)
            return False

    def _after(self, peer: Peer, phase: Phase, horizon: int, *, done: bool) -> None:
        """The plan moves on after a run: the next part or phase, or a retry later."""
        if done and phase is Phase.FULL and peer.full_left:
            peer.full_left = False  # the full run went in parts: the next part at once
        elif done:
            peer.plan.pop(0)
            if not peer.plan:
                peer.compared = peer.plan_version
            elif phase is Phase.NEAR:
                peer.full_after = self._full_deadline(peer, horizon)
        else:
            if not peer.busy:  # (busy: the plan stands, the same run is asked again)
                peer.plan = []
            retry = self.settings.retry_after_s if peer.retry_in is None else peer.retry_in
            peer.next_try, peer.retry_in = self.clock.now() + retry, None

    def _full_deadline(self, peer: Peer, horizon: int) -> float:
        """When the full run must start at the latest: so that its result comes before we
        leave what the near run compared, and before the near run's decisions expire (the
        peer may be past the path it showed: its horizon at its speed from the near run's
        start, :meth:`_decided`), less the margin -- a full run of our whole remaining path
        against the peer's (its beacon's size class).  On the ground: at once."""
        now = self.clock.now()
        if self.vehicle.on_ground:
            return now
        speed = max(self.vehicle.speed_m_s, self.settings.cruise_m_s)
        start, path = self.flight.remaining_path()
        covered = [k - start for k in sorted(peer.covered) if k >= start]
        here = self.vehicle.here()
        left = along_m(path[: (covered[-1] if covered else -1) + 2], here)
        ends = now + left / speed
        if peer.near_run is not None:
            ends = min(ends, self.standing.near_expires(peer))
        grid = self.flight.grid(path)
        m = DEFAULT_LIMITS.public_size(len(path) - 1)
        n = peer.size
        latest = (
            ends
            - self.estimates.seconds(m, grid, fresh=False, n=n)
            - self.settings.failsafe.margin_s
        )
        return max(latest, now)

    def _phases(self, peer: Peer) -> list[tuple[Phase, int]]:
        """The runs a comparison with ``peer`` takes: near (what can be reached soon) when the
        remaining path reaches beyond its horizon, then full (horizon 0: everything)."""
        _, path = self.flight.remaining_path()
        phases = [(Phase.FULL, 0)]
        if self.settings.lookahead_s > 0 and len(path) >= 2:
            horizon = self._horizon_m(peer, path)
            if len(self.flight.near(path, horizon)) < len(path):
                phases.insert(0, (Phase.NEAR, horizon))
        return phases

    def _horizon_m(self, peer: Peer, path: list[tuple[int, int]]) -> int:
        """How far ahead the near run looks: past the worst-case time until the peer could
        be here (a near run that ends before that moment would find nothing), long enough
        for every peer now due to get its near run (one at a time: the estimate counts them
        all), and at least lookahead_s of flight.  What lies beyond is the full run's, which
        follows at once when it is needed before the drone leaves what the near run covered
        (:meth:`_full_deadline`).  A protected-volume run is about 2.5 times a crossing's
        bytes: a near run that waited for the full run's time too would cover everything
        and come too late.  Every term comes from what the beacons and the run sizes already
        tell: the horizon shows Bob nothing about Alice's path."""
        speed = max(self.vehicle.speed_m_s, self.settings.cruise_m_s)  # Bob cuts his path alike
        grid = self.flight.grid(path)
        now = self.clock.now()
        due = [p for p in self.neighbourhood.peers.values() if self.standing.due(p, now)] or [peer]
        runs = sum(
            self.estimates.seconds(2, grid, fresh=p.node not in self.neighbourhood.holder_setups)
            for p in due
        )
        # Nothing can happen before the peer could be here (both at cruise speed at least);
        # reach well past that moment.
        cruise = self.settings.cruise_m_s
        meet = time_to_meet(
            self.vehicle.position[:2], speed, peer, floor_m_s=cruise, measured=False
        )
        meet += NEAR_SLACK_S
        meet = meet if math.isfinite(meet) else 0.0
        seconds = max(self.settings.lookahead_s, runs + self.settings.failsafe.margin_s, meet)
        return round(seconds * speed)

    def _peer_earliest(self, peer: Peer, a: tuple[int, int], b: tuple[int, int]) -> float:
        """The earliest second from now the peer could come within the separation of our
        segment a-b: its distance at cruise speed at least (it may have flown since it was
        last heard), and never before the two drones could meet at all."""
        speed = max(self.vehicle.speed_m_s, self.settings.cruise_m_s)
        cruise = self.settings.cruise_m_s
        meet = time_to_meet(
            self.vehicle.position[:2], speed, peer, floor_m_s=cruise, measured=False
        )
        gap = segment_distance_m(peer.position, a, b) - self.settings.separation.horizontal_m
        reach = max(gap, 0.0) / self.neighbourhood.peer_pace(peer) - self.neighbourhood.silent_for(
            peer
        )
        return max(meet, reach)

    def _before_meeting(self, peer: Peer, start: int, path: list[tuple[int, int]]) -> int:
        """How many of a near run's first segments we leave before the peer could come
        near them (:meth:`_peer_earliest`, less the margin): no volume of the peer's can
        meet them, and a near run without them is smaller and sooner.  At least two
        segments stay; the full run compares everything left."""
        if self.vehicle.on_ground or len(path) <= 3 or not self.settings.lookahead_s:
            return 0
        schedule = self.flight.original_schedule(start)
        tolerance = self.settings.separation.tolerance
        margin = self.settings.failsafe.margin_s
        skip = 0
        for j in range(len(path) - 3):  # (two segments stay)
            earliest = self._peer_earliest(peer, path[j], path[j + 1]) - margin
            if not math.isfinite(earliest) or schedule.window(start + j, tolerance)[1] >= earliest:
                break
            skip += 1
        return skip

    def _bob_horizon(
        self,
        horizon: int,
        start: int,
        path: list[tuple[int, int]],
        peer: Peer,
        grid: GridSpec,
        *,
        n: int,
        fresh: bool,
    ) -> int:
        """How far the peer cuts its path in a near run where ours is ``path`` (from segment
        ``start``): as far as it can fly (at its speed, at least cruise) until we leave the
        last of our segments, late by our tolerance, plus the margin and the separation.  Our
        near segments are then flown before the peer can be past its cut, and the full run
        need not compare them again (:meth:`_decided_by_near`) -- as far as the peer's answer
        covers it: the peer answers with the ``n`` segments we ask for whatever the horizon
        (:meth:`_near_ask`), and says how much of the horizon they cover.  Only when the run,
        its estimate stretched by ``NEAR_SLACK`` (the OT setup's computing, collisions),
        still ends before the peer could be here; otherwise -- and on the ground, whose
        windows never close -- ``horizon`` as asked, stretched to the same time ahead at the
        peer's speed (the near run's decisions last as long as the horizon at the peer's
        speed, :meth:`_decided`)."""
        # The same time ahead as ours: the peer may fly faster than we do.
        ours = max(self.vehicle.speed_m_s, self.settings.cruise_m_s)
        theirs = self.neighbourhood.peer_pace(peer)
        horizon = max(horizon, math.ceil(horizon * theirs / ours))
        schedule = self.flight.original_schedule(start)
        last = start + len(path) - 2
        end = schedule.window(last, self.settings.separation.tolerance)[1]
        if not math.isfinite(end):
            return horizon
        reach = theirs * (end + self.settings.failsafe.margin_s)
        longer = math.ceil(reach + self.settings.separation.horizontal_m)
        if longer <= horizon:
            return horizon
        m = DEFAULT_LIMITS.public_size(len(path) - 1)
        return horizon if self._too_late(peer, m, n, grid, fresh=fresh) else longer

    def _near_ask(
        self, path: list[tuple[int, int]], peer: Peer, grid: GridSpec, *, fresh: bool
    ) -> int:
        """How many segments a near run asks of the peer's path (``Hello.n``, exactly that
        many: a run's size on the air then shows nothing of the peer's path): as many as we
        compare, or four when a run with four still comes in time (its estimate stretched by
        ``NEAR_SLACK``) -- short legs of the peer's within the horizon are then decided by
        the near run, not left to the full run -- never more than its size class.  Public
        facts and our own path only: our size, its size class, the urgency."""
        m = DEFAULT_LIMITS.public_size(len(path) - 1)
        ask = min(m, peer.size)
        more = min(max(m, NEAR_ASK), peer.size)
        if more > ask and not self._too_late(peer, m, more, grid, fresh=fresh, queue=True):
            return more
        return ask

    def _too_late(
        self, peer: Peer, m: int, n: int, grid: GridSpec, *, fresh: bool, queue: bool = False
    ) -> bool:
        """Whether an m x n near run, its estimate stretched by ``NEAR_SLACK`` (and, with
        ``queue``, by the first runs the channel still carries, :meth:`_first_runs`), would
        come too late for the peer."""
        seconds = self.estimates.seconds(m, grid, fresh=fresh, n=n) * NEAR_SLACK
        if queue:
            seconds *= self._first_runs()
        return too_late(seconds, self.neighbourhood.urgency(peer), self.settings.failsafe)

    def _first_runs(self) -> float:
        """How many first runs one channel in flight still carries, ours among them, at
        least one: the pairs of drones in range, in the share of our own peers we are Alice
        for and have not compared yet -- their first runs take turns on the air (busy_four_
        eu868's six pairs asked four segments each and their 22 KB first runs queued up past
        the meetings: 3.1 precautions a replay, 2.4 so; inflight_star's three pairs still
        ask four where it counts).  A crowded sky (:meth:`_lazy_s`) compares only the
        urgent peers and keeps its asks (asking less there cost precautions).  From the
        neighbourhood's size and our own runs only."""
        if self.endpoint.channels > 1 or self.vehicle.on_ground or self._lazy_s() is not None:
            return 1.0
        ours = [p for p in self.neighbourhood.peers.values() if self.standing.pending(p)]
        if not ours:
            return 1.0
        drones = len(self.neighbourhood.peers) + 1
        waiting = sum(1 for p in ours if p.near_run is None) / len(ours)
        return max(1.0, waiting * drones * (drones - 1) / 2)

    def _decided_by_near(self, peer: Peer, start: int, path: list[tuple[int, int]]) -> int:
        """How many of a full run's first segments it need not compare: those the near run
        decided (:meth:`_decided`), and those we leave (late by our tolerance) before the
        full run's result can come -- for them it could only come too late; the fail-safe
        watches them until the near run's decision expires.  A full run without them is
        smaller and sooner."""
        if peer.near_run is None or self.vehicle.on_ground:
            return 0
        decided = self.standing.decided(peer)
        schedule = self.flight.original_schedule(start)
        tolerance = self.settings.separation.tolerance
        grid = self.flight.grid(path)
        skip = 0
        for j in range(len(path) - 2):  # (one segment stays)
            k = start + j
            if k in decided:
                skip += 1
                continue
            if k not in peer.covered:
                break
            m = DEFAULT_LIMITS.public_size(len(path) - 2 - j)
            n = min(m, BOB_GUESS)
            if schedule.window(k, tolerance)[1] >= self.estimates.seconds(
                m, grid, fresh=False, n=n
            ):
                break
            skip += 1
        return skip

    def _full_chunk(self, peer: Peer, start: int, path: list[tuple[int, int]]) -> int:
        """How many segments of ``path`` (from segment ``start``, what a full run has left to
        compare) the next full run takes: all of them, unless a run of all would come too
        late for the first -- later than we enter it, and than the peer could be here -- and
        a smaller one would not: then the most, in powers of two, that come in time (at least
        two).  The next run takes the rest at once: the full run goes in parts, the urgent
        part first.  On the ground (nothing is urgent) all of them.  Never more than the peer
        answers (:meth:`_most_segments`)."""
        segments = min(len(path) - 1, self._most_segments(peer, path))
        if self.vehicle.on_ground or segments <= 2:
            return segments
        schedule = self.flight.original_schedule(start)
        enter = schedule.window(start, self.settings.separation.tolerance)[0]
        deadline = max(enter, self.neighbourhood.urgency(peer))
        grid = self.flight.grid(path)
        n = peer.size
        fresh = peer.node not in self.neighbourhood.holder_setups
        m = DEFAULT_LIMITS.public_size(segments)
        while m > 2:
            seconds = self.estimates.seconds(m, grid, fresh=fresh, n=n)
            if not too_late(seconds, deadline, self.settings.failsafe):
                break
            m //= 2
        return min(m, segments)

    def _most_segments(self, peer: Peer, path: list[tuple[int, int]]) -> int:
        """The most segments of ``path`` one run may take: what the peer answers
        (:data:`companion.runs.budget.MAX_RUN_WORK`, with its size class and our grid)."""
        n = peer.size
        grid = self.flight.grid(path)
        m = MAX_SEGMENTS
        while m > 1 and run_work(m, n, grid.range) > MAX_RUN_WORK:
            m //= 2
        return m

    async def _run(self, peer: Peer, phase: Phase, horizon: int) -> bool:
        """One run; True when it ended with a result (or had nothing to compare)."""
        start, path = self.flight.remaining_path()
        current = start
        if phase is Phase.NEAR:
            skip = self._before_meeting(peer, start, path)
            if skip:  # what is left of the horizon after the segments skipped
                here = self.vehicle.here()
                left = horizon - along_m(path[: skip + 1], here)
                peer.settled |= set(range(start, start + skip))  # no volume of its can meet them
                start, path = start + skip, near_cut(path[skip:], max(left, 1.0), least=2)
            else:
                path = self.flight.near(path, horizon)
            path = path[: self._most_segments(peer, path) + 1]
        else:
            skip = self._decided_by_near(peer, start, path)
            start, path = start + skip, path[skip:]
            chunk = self._full_chunk(peer, start, path)
            peer.full_left = chunk < len(path) - 1
            path = path[: chunk + 1]
        if start == current:  # the leg we fly: from here on
            path = self.flight.from_here(path)
        if len(path) < 2:
            return True
        neighbour = self.neighbourhood.registry.get(peer.node)
        if neighbour is None or neighbour.fingerprint != peer.identity:
            self.neighbourhood.forget(
                peer.node
            )  # its certificate is gone or taken over: not our peer
            return False
        op = neighbour.operator
        if self.settings.suite is Suite.PAPER and not op.paper_keys:
            # Bob's unproven keys could make what he decrypts depend on our path: only with
            # drones whose operator vouches for them (trust.operator.paper_keys).
            error = f"operator {op.name} is not trusted with paper-suite keys (paper_keys)"
            self.record(EventKind.RUN_FAILED, PeerFailure(peer=peer.node, phase=phase, error=error))
            return False
        try:
            ticket = self.ledger.admit(
                peer.identity,
                op.key.fingerprint,
                op.max_runs_per_hour,
                self.clock.wall(),
                ALICE,
            )
        except BudgetExceeded as exc:
            self.record(EventKind.BUDGET, PeerFailure(peer=peer.node, error=str(exc)))
            return False
        done = await self._compare(peer, phase, horizon, start, path, neighbour)
        if not done:
            self.ledger.refund(ticket)  # no result: a retry must not use up our runs
        return done

    async def _compare(
        self,
        peer: Peer,
        phase: Phase,
        horizon: int,
        start: int,
        path: list[tuple[int, int]],
        neighbour: Neighbour,
    ) -> bool:
        """The run itself (a fresh OT setup again if the peer lost ours).  A near run asks
        the peer for a little more of its path than it shows of its own (:meth:`_bob_horizon`)
        so that the full run after it can leave out what the near run decided."""
        peer.role = Role.ALICE
        peer.busy = False
        asked = horizon
        for attempt in range(2):
            grid = self.flight.grid(path)
            setup = self.neighbourhood.holder_setups.get(peer.node)
            ask = 0  # a full run: the peer's whole path
            if phase is Phase.NEAR:
                fresh = setup is None
                ask = self._near_ask(path, peer, grid, fresh=fresh)
                horizon = self._bob_horizon(asked, start, path, peer, grid, n=ask, fresh=fresh)
            began = await self._begin(
                peer, phase, (horizon, ask), start, path, neighbour, grid, setup
            )
            if began is None:
                return False
            alice, needed = began
            try:
                report = await self._exchange(peer, alice, grid, needed, neighbour, setup is None)
            except PeerRefused as exc:
                if self._refused(peer, phase, exc, grid, first=attempt == 0):
                    continue  # the peer lost our setup: a fresh one
                return False
            except PeerElsewhere:
                self._later(peer, phase)  # in a run on another channel: as if BUSY
                return False
            except (ProtocolError, CompanionError) as exc:
                self._failed(peer, phase, exc)
                return False
            break
        else:
            return False
        if phase is Phase.NEAR:  # its decisions hold as far as the peer's answer reaches
            peer.near_run = (report.started, horizon * report.cover // COVER_ALL)
        await self._accept(peer, phase, start, path, alice, report)
        return True

    async def _exchange(
        self,
        peer: Peer,
        alice: Alice,
        grid: GridSpec,
        needed: float,
        neighbour: Neighbour,
        fresh: bool,
    ) -> RunReport:
        """Our machine's messages over the link, on the air and watched by the fail-safe
        (:meth:`Guard.watch`) while they last."""
        watchdog = self.ctx.spawn(self.guard.watch(peer, alice, grid, needed), "watch")
        self.air.sessions += 1
        self.air.own = alice

        def secure(session: int, cert: Certificate = neighbour.cert) -> Initiator:
            route = Route(self.settings.node, peer.node, session)
            return Initiator(self.identity, cert, route, self.clock.wall())

        def check_keys(boot: bytes, public: bytes) -> bool:
            """The keys Bob shows are those his signed beacons announced."""
            key = neighbour.beacon_key
            return key is not None and keys_hash(boot, key, public) == neighbour.keys_hash

        progress = RunProgress(
            self.settings.node,
            self.endpoint,
            peer.node,
            Role.ALICE,
            expected_bytes=functools.partial(self.estimates.run_bytes, alice, grid, fresh=fresh),
            ends_at=self.guard.ends_at,
        )
        try:
            with progress:
                return await run_alice(
                    self.endpoint,
                    peer.node,
                    alice,
                    secure=secure,
                    check_keys=check_keys,
                    timeout=self.settings.run_timeout_s,
                    alive=functools.partial(self.neighbourhood.still_heard, peer.node),
                )
        finally:
            self.air.sessions -= 1
            self.air.own = None
            self.guard.running = None
            watchdog.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watchdog

    async def _begin(
        self,
        peer: Peer,
        phase: Phase,
        asks: tuple[int, int],
        start: int,
        path: list[tuple[int, int]],
        neighbour: Neighbour,
        grid: GridSpec,
        setup: HolderSetup | None,
    ) -> tuple[Alice, float] | None:
        """Our machine for the run (``asks``: the horizon and the size asked of the peer's
        path) and the seconds it should take (None: our path cannot be
        compared on this grid, recorded); a precaution at once if even the smallest Bob
        makes the result too late (the watch re-checks with his real size)."""
        try:
            route, volumes = self._own_route(grid, start, path)
            alice = Alice(
                route,
                grid,
                suite=self.settings.suite,
                setup=setup,
                horizon_m=asks[0],
                ask_n=asks[1],
                volumes=volumes,
                ot_security=self.settings.ot_security,
                trusted_keys=neighbour.operator.paper_keys,
            )
        except ProtocolError as exc:
            self.record(
                EventKind.RUN_FAILED, PeerFailure(peer=peer.node, phase=phase, error=str(exc))
            )
            return None
        needed = self.estimates.seconds(alice.m, grid, fresh=setup is None, n=1)
        meet = self.neighbourhood.urgency(peer)
        self.record(
            EventKind.RUN_STARTED,
            RunStarted(
                peer=peer.node,
                phase=phase,
                segments=alice.m,
                first_segment=start,
                estimate_s=round(needed, 1),
                time_to_meet_s=round(meet, 1) if math.isfinite(meet) else None,
            ),
        )
        if act_now(needed, meet, self.neighbourhood.earliest(peer), self.settings.failsafe):
            await self.guard.precaution(peer, needed, meet)
        return alice, needed

    def _failed(self, peer: Peer, phase: Phase, exc: ProtocolError | CompanionError) -> None:
        """A run that ended without a result, recorded by what ended it."""
        if isinstance(exc, AuthenticationError):
            failure = PeerFailure(peer=peer.node, phase=phase, auth=str(exc))
        elif isinstance(exc, ConsistencyError):
            # The peer's OT extension is not the honest one: it probed our Delta.  Drop the
            # setup (a wrong guess must not be followed by another on the same Delta).
            self.neighbourhood.holder_setups.pop(peer.node, None)
            failure = PeerFailure(peer=peer.node, phase=phase, deviated=str(exc))
        else:
            failure = PeerFailure(peer=peer.node, phase=phase, error=str(exc))
        self.record(EventKind.RUN_FAILED, failure)

    def _later(self, peer: Peer, phase: Phase) -> None:
        """The peer's own run is on the air: not a failure, ask again soon (at a random
        moment: others it turned away are waiting too)."""
        low, high = self.settings.busy_retry_s
        peer.retry_in = low + (high - low) * secrets.randbelow(1001) / 1000
        peer.busy = True
        self.record(EventKind.PEER_BUSY, PeerNote(peer=peer.node, phase=phase))

    def _refused(
        self, peer: Peer, phase: Phase, exc: PeerRefused, grid: GridSpec, *, first: bool
    ) -> bool:
        """The peer refused our run before any work: True to run again at once (it lost our
        OT setup: a fresh one), else what the refusal means is recorded."""
        if exc.code is Refusal.UNKNOWN_SETUP and first:
            self.neighbourhood.holder_setups.pop(peer.node, None)  # the peer lost it: start afresh
            self.record(EventKind.SETUP_RENEWED, PeerNote(peer=peer.node))
            return True
        if exc.code is Refusal.ROLE:
            peer.role = Role.BOB  # the peer already resolved this pair as Alice
            self.record(EventKind.YIELDED, PeerNote(peer=peer.node, reason="the peer is Alice"))
            return False
        if exc.code is Refusal.BUSY:
            self._later(peer, phase)
            return False
        if exc.code is Refusal.UNKNOWN_PEER:
            self.sender.send_certificate()  # it lacks our certificate: beacon it
        box = exc.code is Refusal.BOX  # off our beacons, or beyond its limits
        self.record(
            EventKind.RUN_FAILED,
            PeerFailure(
                peer=peer.node,
                phase=phase,
                refused=exc.code.name,
                box_radius_m=grid.radius_m if box else None,  # the box we asked for
                resolution_mm=grid.resolution_mm if box else None,
            ),
        )
        return False

    async def _accept(
        self,
        peer: Peer,
        phase: Phase,
        start: int,
        path: list[tuple[int, int]],
        alice: Alice,
        report: RunReport,
    ) -> None:
        """A run's result: keep the OT setup, note what it covered and flagged, release a
        precaution it settles, and plan the edit again."""
        if alice.setup is not None:
            self.neighbourhood.holder_setups[peer.node] = alice.setup
        flagged = {start + j for j, hit in enumerate(report.hits) if hit}
        covered = set(range(start, start + len(path) - 1))
        peer.conflicts = (peer.conflicts - covered) | flagged
        peer.covered |= covered
        if phase is Phase.FULL:
            peer.settled |= covered
        self.record(
            EventKind.RESULT,
            RunResult(
                peer=peer.node,
                phase=phase,
                hits=report.hits,
                first_segment=start,
                flagged=sorted(flagged),
                bytes=report.bytes_sent,
                auth_bytes=report.auth_bytes_sent,
                cpu_s=round(report.cpu_s, 3),
                run_s=round(report.wall_s, 1),
            ),
        )
        if phase is Phase.FULL or covered >= self.edits.precaution.get(peer.node, set()):
            await self.edits.release(peer.node)
        await self.edits.replan(f"result of the {phase} run with {peer.node}")

    def _own_route(
        self, grid: GridSpec, start: int, path: list[tuple[int, int]]
    ) -> tuple[PathRoute, VolumeSpec]:
        """What we compare as Alice: the original mission's path from segment ``start`` on
        the grid, with its bands and windows (:mod:`companion.mission.schedule`) -- each band
        reaching as far as our raises take it (:meth:`OwnFlight.reaches`) -- and the run's
        volume parameters (epoch: now)."""
        epoch = int(self.clock.wall())
        volumes = self.estimates.volumes(grid, epoch)
        points = grid.project_path(path)
        if volumes == CROSSING:
            return PathRoute(points), volumes
        schedule = self.flight.original_schedule(start)
        bands, windows = route_volumes(
            schedule,
            start,
            len(path) - 1,
            grid.resolution_mm,
            self.flight.wall_of_state() - epoch,
            self.settings.separation.tolerance,
            self.flight.reaches(),
        )
        return PathRoute(points, bands, windows), volumes
