"""What a companion knows, and the reckoning every part of it shares.

Its settings and credentials; the state of its drone (position, mission, flown path, levels)
and of its peers; and the estimates the runs, the fail-safe and the answers all use: which
drone of a pair is Alice (:func:`companion.beacon.alice_of`), how soon a peer could be here
(:func:`companion.peers.time_to_meet`), how long a run takes on this link
(:func:`companion.failsafe.run_seconds`) and what is left of the path to fly.
:class:`~companion.runtime.Companion` is this core with one part per concept on top:
beaconing, Alice's runs, Bob's answers, and the edits and precautions.
"""

from __future__ import annotations

import asyncio
import logging
import math
import secrets
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.compact_plan import message_sizes
from protocol.grid import GridSpec
from protocol.intersection import BobKeys
from protocol.ot.setup import DEFAULT_SECURITY, ChooserSetup, HolderSetup
from protocol.wire import Suite

from . import logs
from .auth.beacon_keys import BeaconKeys
from .auth.session import BOOT_SIZE, Identity
from .auth.trust import TrustStore
from .autopilot import Autopilot
from .beacon import alice_of, keys_hash
from .beacon_budget import beacon_interval
from .budget import RunLedger, RunLimits
from .events import WARNINGS, Event, EventKind
from .failsafe import FailsafeSettings, run_seconds
from .flightpath import FlightPath
from .link.endpoint import LinkEndpoint
from .mission import MissionItem
from .neighbours import Neighbours
from .peers import FRESH_S, Peer, distance_m, near_cut, time_to_meet
from .planner import OffsetSettings
from .radio import RadioTurns
from .roles import Role
from .state import StateStore

log = logging.getLogger("companion")
NEAR_SEGMENTS = 2  # each side of a near run compares at least its next two segments
SIGNED_EVERY_S = 300.0  # a signed beacon at least this often (for drones that missed one),
SIGNED_EVERY = 30  # and at most every 30th beacon (a duty cycle stretches beacons to minutes)
ASKED_AGAIN = 0.5  # asked for, a certificate or signed beacon at most every half interval


@dataclass(frozen=True)
class CompanionSettings:
    node: int
    autopilot_url: str
    ardupilot: bool = False
    suite: Suite = Suite.COMPACT
    ot_security: int = DEFAULT_SECURITY  # kappa of the OT setups we start (as Alice)
    offset: OffsetSettings = field(default_factory=OffsetSettings)
    beacon_interval_s: float = 10.0
    initiation_range_m: float = 5000.0
    grid_resolution_mm: int = 500
    grid_radius_m: float = 500.0  # smallest comparison box; doubled until it holds Alice's path
    max_box_radius_m: float = 64000.0  # largest box we answer in (as Bob): 40 m/s for 27 min
    min_grid_resolution_mm: int = 100  # finest grid we answer on (as Bob)
    max_runs_per_peer: int = 8  # runs a certified drone may ask of us per window
    max_runs_total: int = 64  # runs all peers together may ask of us per window
    max_answer_bits_per_peer: int = 256  # answer bits (segments x runs) one drone may get
    run_window_s: float = 3600.0
    max_clock_skew_s: float = 30.0  # beacons and run requests further off our clock: refused
    run_timeout_s: float | None = None
    retry_after_s: float = 30.0
    lookahead_s: float = 60.0  # the near run covers at least this much flight (0: no near run)
    cruise_m_s: float = 10.0  # speed assumed for the look-ahead when nothing better is known
    failsafe: FailsafeSettings = field(default_factory=FailsafeSettings)


@dataclass(frozen=True)
class Credentials:
    """Who the companion is (its key and its operator's certificate), whom it deconflicts
    with (the trust store) and where it keeps what must survive a restart."""

    identity: Identity
    trust: TrustStore
    state_dir: Path


def mission_version(path: FlightPath) -> int:
    """16-bit digest of the ground track: altitude edits do not change it."""
    import hashlib

    digest = hashlib.sha256(repr(path.points).encode()).digest()
    return int.from_bytes(digest[:2], "big")


def same_track(a: list[MissionItem], b: list[MissionItem]) -> bool:
    """The same items in the same places (altitudes and the current mark aside)."""
    return len(a) == len(b) and all(
        (x.command, x.x, x.y, x.mission_type) == (y.command, y.x, y.y, y.mission_type)
        for x, y in zip(a, b, strict=True)
    )


def box_radius_m(path: list[tuple[int, int]], centre: tuple[int, int], minimum: float) -> float:
    """The comparison box's radius: ``minimum``, doubled until it holds the path with room
    to spare (the box's edge then stays clear of Alice's path)."""
    extent = max((distance_m(centre, p) for p in path), default=0.0) * 1.1 + 50.0
    radius = minimum
    while radius < extent:
        radius *= 2
    return radius


class CompanionCore:
    """The state and shared reckoning of one companion (see the module)."""

    def __init__(
        self,
        settings: CompanionSettings,
        endpoint: LinkEndpoint,
        autopilot: Autopilot,
        credentials: Credentials,
    ) -> None:
        self.settings = settings
        self.endpoint = endpoint
        self.autopilot = autopilot
        self.clock = endpoint.clock
        self.identity = credentials.identity
        if self.identity.cert.node != settings.node:
            raise ValueError(
                f"the certificate is for node {self.identity.cert.node}, not {settings.node}"
            )
        self.bob_keys = BobKeys.generate() if settings.suite is Suite.PAPER else None
        self.boot = secrets.token_bytes(BOOT_SIZE)  # new at every start: peers drop our setups
        self.beacon_keys = BeaconKeys()  # new at every start too
        public = self.bob_keys.public_bytes() if self.bob_keys is not None else b""
        self.keys_hash = keys_hash(self.boot, self.beacon_keys.public, public)
        self.store = StateStore(credentials.state_dir)
        self.neighbours = Neighbours(
            credentials.trust,
            self.store,
            self.identity.cert,
            self.beacon_keys,
            settings.max_clock_skew_s,
        )
        self.ledger = RunLedger(
            self.store,
            RunLimits(
                settings.max_runs_per_peer,
                settings.max_runs_total,
                settings.run_window_s,
                settings.max_answer_bits_per_peer,
            ),
        )
        self._order: int | None = None  # (time, counter) of our last beacon
        self._cert_sent = -math.inf
        self._unknown_refused = -math.inf
        self._signed_at = -math.inf  # our last signed beacon
        self._sign_next = True  # the next beacon is a signed one
        self._cert_wanted = False
        self._ignored: set[bytes] = set()  # untrusted drones logged already
        self._alerted: dict[int, float] = {}
        self._asking: dict[int, tuple[float, float]] = {}  # node -> (next ask, interval)
        self.rejected: dict[str, int] = {}  # beacons dropped, by reason
        self.beacon_bytes = 0  # beacon payloads we sent (position and certificate)
        self.beacons_sent = {"signed": 0, "tagged": 0, "certificate": 0}
        self.holder_setups: dict[int, HolderSetup] = {}  # peer -> ours as Alice
        self.chooser_setups: dict[int, dict[bytes, ChooserSetup]] = {}  # peer -> ours as Bob
        self.peers: dict[int, Peer] = {}
        self.events: list[Event] = []
        self.original: list[MissionItem] = []
        self.mission: list[MissionItem] = []
        self.home: tuple[int, int, float] | None = None  # lat, lon degE7, alt AMSL
        self.path = FlightPath(())  # the flown ground path of the original mission
        self.levels: dict[int, int] = {}  # segment -> altitude level, as uploaded
        self.flagged: set[int] = set()  # segments the comparisons found in conflict
        self.precaution: dict[int, set[int]] = {}  # peer -> segments climbed as a precaution
        self.position: tuple[int, int, float] = (0, 0, 0.0)  # lat, lon degE7, alt AMSL
        self.relative_alt = 0.0
        self.speed_m_s = 0.0
        self.current_item = 0
        self.has_flown = False  # airborne at least once since the companion started
        self._heard_autopilot = time.monotonic()  # the last position (real seconds)
        self._tasks: list[asyncio.Task[None]] = []
        self._children: set[asyncio.Task[None]] = set()
        self._busy = asyncio.Lock()
        self._radio = RadioTurns()  # one run on the air at a time, as Alice or Bob
        self._edit_lock = asyncio.Lock()
        self._wake = asyncio.Event()
        self._beacon_now = asyncio.Event()
        self._cert_now = asyncio.Event()
        self._cert_now.set()  # our certificate, then a signed beacon: peers can check us at once
        self._sessions = 0  # runs on the air (as Alice or Bob)
        self._answering = 0  # runs we answer as Bob
        self._holding: set[int] = set()  # peers we hold for
        self._running: tuple[int, float] | None = None  # our run's peer, its expected end
        self._ground_wait: float | None = None  # since when a run waits for a quiet channel
        self.epoch = 0.0

    def record(self, kind: EventKind, **detail: Any) -> None:
        """An event at link seconds since :attr:`epoch` (the start, or the replay's zero),
        logged as ``key=value`` text and as a JSON line (:mod:`companion.logs`)."""
        t = self.clock.now() - self.epoch
        self.events.append(Event(t, kind, detail))
        level = logging.WARNING if kind in WARNINGS else logging.INFO
        text = f"node {self.settings.node}: {kind.replace('_', ' ')}"
        logs.event(log, level, kind, text, t_s=round(t, 1), **detail)

    def _spawn(self, work: Any) -> None:
        task = asyncio.create_task(work)
        self._children.add(task)
        task.add_done_callback(self._ended)

    def _ended(self, task: asyncio.Task[None]) -> None:
        """A task of ours ended: a failure is logged with its traceback and recorded (a
        companion whose beacons or answers died must say so, not go quiet)."""
        self._children.discard(task)
        if task.cancelled():
            return
        exc = task.exception()
        if exc is not None:
            log.error("node %d: task %s failed", self.settings.node, task.get_name(), exc_info=exc)
            self.record(EventKind.TASK_FAILED, task=task.get_name(), error=repr(exc))

    @property
    def in_run(self) -> bool:
        """A run is on the air, as Alice or as Bob."""
        return self._sessions > 0

    @property
    def comparing(self) -> bool:
        """A comparison as Alice is under way or half done (a drone about to take off waits
        for it)."""
        return self._busy.locked() or any(p.plan for p in self.peers.values())

    @property
    def on_ground(self) -> bool:
        return self.relative_alt < 1.0

    @property
    def version(self) -> int:
        return mission_version(self.path)

    @property
    def beacon_interval(self) -> float:
        """The configured interval, stretched on duty-cycled links so beacons use at most
        5 % of the budget (EU868 SF9: one beacon per ~5 minutes)."""
        return beacon_interval(self.endpoint.profile, self.settings.beacon_interval_s)

    @property
    def _signed_every_s(self) -> float:
        """A signed beacon at least this often: 5 minutes, or every 30th beacon where a duty
        cycle stretches the interval to minutes."""
        return max(SIGNED_EVERY_S, SIGNED_EVERY * self.beacon_interval)

    @property
    def _asked_every_s(self) -> float:
        """How often we answer requests for our certificate or signed beacon (and refuse
        runs of drones we do not know yet): every half *configured* beacon interval, at least
        2 s -- not the interval a duty cycle stretches to minutes: discovery must not wait
        for that (the duty-cycle budget itself spaces the frames)."""
        return max(2.0, ASKED_AGAIN * self.settings.beacon_interval_s)

    def _should_compare(self, peer: Peer, now: float) -> bool:
        """Pending, not waiting for a retry, and the peer can check our requests: its tagged
        beacons carry a tag for us (it holds our beacon key, so it heard us)."""
        neighbour = self.neighbours.get(peer.node)
        knows_us = neighbour is not None and neighbour.knows_us
        return now >= peer.next_try and knows_us and self._pending(peer)

    def _pending(self, peer: Peer) -> bool:
        """We are Alice for this peer, it is in range, and its paths are not compared yet."""
        me = (self.on_ground, self.settings.node)
        them = (peer.beacon.on_ground, peer.node)
        if peer.role is Role.BOB:
            return False
        if peer.role is None and alice_of(me, them) != self.settings.node:
            return False
        if self.settings.suite not in peer.beacon.suites:
            return False
        if self.position[:2] == (0, 0):
            return False
        if distance_m(self.position[:2], peer.position) > self.settings.initiation_range_m:
            return False
        return peer.compared != (peer.beacon.mission_version, self.version)

    def _peer_speed(self, peer: Peer) -> float:
        """The speed the fail-safe assumes for a peer: its measured speed, at least the
        floor; an airborne peer not measured lately (heard too seldom, or silent since) may
        fly at cruise speed whatever it did when last measured."""
        floor = self.settings.failsafe.floor_m_s
        if not peer.beacon.on_ground and (not peer.measured or self._silent_for(peer) > 0):
            floor = max(floor, self.settings.cruise_m_s)
        return max(peer.speed_m_s, floor)

    @property
    def _silence_s(self) -> float:
        """How long a peer may go unheard in the normal course: beacons are deferred up to
        three intervals while runs are on the air (and jittered), measurements age FRESH_S."""
        return 4.0 * self.beacon_interval + FRESH_S

    def _silent_for(self, peer: Peer) -> float:
        """Seconds since the peer was last heard if it has fallen silent, else 0."""
        age = self.clock.now() - peer.heard_at
        return age if age > self._silence_s else 0.0

    def _urgency(self, peer: Peer) -> float:
        return time_to_meet(
            self.position[:2],
            self.speed_m_s,
            peer,
            floor_m_s=self.settings.failsafe.floor_m_s,
            peer_floor_m_s=self._peer_speed(peer),
            now=self.clock.now(),
            silent_after_s=self._silence_s,
        )

    def _remaining_path(self) -> tuple[int, list[tuple[int, int]]]:
        """The path still to fly: all of it before the first take-off; in flight from the
        leg to the current item; landed after flying, from there on -- and nothing (the
        landing point) once the current item is the last one on the path, so a drone whose
        mission is over never compares, as Alice, a path it will not fly again."""
        if self.on_ground and not self.has_flown:
            return 0, self.path.points
        start = self.path.start_at(self.current_item)
        points = self.path.points[start:]
        last = max((i for v in self.path.vertices for i in v.items), default=0)
        if self.on_ground and self.current_item >= last:
            return len(self.path.points) - 1, points[-1:]
        return start, points

    def _grid(self, path: list[tuple[int, int]]) -> GridSpec:
        lat, lon = self.position[:2]
        radius = box_radius_m(path, (lat, lon), self.settings.grid_radius_m)
        return GridSpec.geo(
            lat, lon, resolution_mm=self.settings.grid_resolution_mm, radius_m=radius
        )

    def _here(self) -> tuple[int, int] | None:
        """Where the drone is, for distances along its path (None on the ground)."""
        return None if self.on_ground or self.position[:2] == (0, 0) else self.position[:2]

    def _seconds(
        self, m: int, grid: GridSpec, *, fresh: bool, n: int | None = None, skip: int = 0
    ) -> float:
        """Link seconds an m x n run (n unknown: Bob's size taken as Alice's) will need from
        now, its first ``skip`` messages already exchanged."""
        if self.settings.suite is not Suite.COMPACT:
            return 0.0
        sizes = message_sizes(
            m, m if n is None else n, grid, fresh_setup=fresh, ot_security=self.settings.ot_security
        )[skip:]
        return run_seconds(
            sizes,
            self.endpoint.profile,
            loss=self.settings.failsafe.loss,
            duty=self.endpoint.duty,
            now=self.clock.now(),
        )

    def _near(self, path: list[tuple[int, int]], horizon: int) -> list[tuple[int, int]]:
        """The part of the remaining path a run with this horizon compares (a full run's
        horizon is 0: all of it)."""
        return near_cut(path, horizon, self._here(), least=NEAR_SEGMENTS)

    def _forget(self, node: int) -> None:
        self.peers.pop(node, None)
        self._drop_setups(node)

    def _drop_setups(self, node: int) -> None:
        """The OT setups we share with ``node`` (both roles)."""
        self.holder_setups.pop(node, None)
        self.chooser_setups.pop(node, None)
