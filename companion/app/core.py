"""What a companion knows, and the reckoning every part of it shares.

Its settings and credentials; the state of its drone (position, mission, flown path, levels)
and of its peers; and the estimates the runs, the fail-safe and the answers all use: which
drone of a pair is Alice (:func:`companion.neighbours.beacon.alice_of`), how soon a peer could be
here (:func:`companion.neighbours.peers.time_to_meet`), how long a run takes on this link
(:func:`companion.runs.failsafe.run_seconds`) and what is left of the path to fly.
:class:`~companion.app.runtime.Companion` is this core with one part per concept on top:
beaconing, Alice's runs, Bob's answers, and the edits and precautions.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import math
import secrets
from collections.abc import Coroutine, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from companion.app import logs
from companion.app.state import StateStore
from companion.auth.beacon_keys import BeaconKeys
from companion.auth.session import BOOT_SIZE, Identity
from companion.auth.trust import TrustStore
from companion.events import WARNINGS, Event, EventKind, Payload, Retimed, TaskFailed
from companion.mission.autopilot import AutopilotBase
from companion.mission.flight_model import MAX_PREDICTION_S, Kinematics
from companion.mission.flightpath import FlightPath, flight_path
from companion.mission.items import NAV_LOITER_TIME, NAV_WAYPOINT, MissionItem
from companion.mission.levels import Slots
from companion.mission.planner import Edit, OffsetSettings
from companion.mission.schedule import (
    Schedule,
    SeparationSettings,
    Vehicle,
    off_schedule,
    predict,
    run_volumes,
)
from companion.mission.vehicle import VehicleState
from companion.neighbours.beacon import alice_of, keys_hash
from companion.neighbours.peers import Peer, distance_m, near_cut, time_to_meet
from companion.neighbours.registry import Neighbours
from companion.neighbours.sender import BeaconSender, Cadence
from companion.radio.endpoint import LinkEndpoint
from companion.runs.budget import RunLedger, RunLimits
from companion.runs.failsafe import FailsafeSettings, run_seconds
from companion.runs.roles import Role
from companion.runs.turns import RadioTurns
from companion.tasks import spawn
from protocol.compact.plan import message_sizes
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import CROSSING, VolumeSpec
from protocol.intersection import Alice
from protocol.messages import Suite
from protocol.ot.setup import DEFAULT_SECURITY, ChooserSetup, HolderSetup
from protocol.paper.keys import BobKeys
from protocol.run import DEFAULT_LIMITS

log = logging.getLogger("companion")
OVER_ITEM_M = 5.0  # this close to its current item's point, the vehicle is holding there
TIMING_LOOK_S = 180.0  # how far ahead the timing watch predicts (the full schedule is kept)
TIMING_EVERY_S = 5.0  # and how often
PREDICTIONS_KEPT = 8  # schedules remembered for a vehicle state (several paths and limits)
NEAR_SEGMENTS = 2  # each side of a near run compares at least its next two segments
ASK_BACKOFF_S = 30.0  # asking a drone again for what its beacons lack: at most this far apart
# (or four beacon intervals where a duty cycle stretches them) -- at 30 % loss one exchange
# of certificates fails about one time in two, and a backoff to 5 minutes left a drone
# unknown to its peer for 6 minutes in about one replay in fifty (it took off uncompared)


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
    grid_resolution_mm: int = 2000  # 2 m cells: 15 m separation is 9 (docs/companion.md)
    grid_radius_m: float = 500.0  # smallest comparison box; doubled until it holds Alice's path
    max_box_radius_m: float = 64000.0  # largest box we answer in (as Bob): 40 m/s for 27 min
    # Farthest from us a requester's box may be centred (as Bob): a drone we hear on a LoRa
    # radio (km to tens of km), not a claim 50 km off.
    max_peer_range_m: float = 30000.0
    min_grid_resolution_mm: int = 100  # finest grid we answer on (as Bob)
    max_runs_per_peer: int = 8  # runs a certified drone may ask of us per window
    max_runs_total: int = 64  # runs all peers together may ask of us per window
    max_answer_bits_per_peer: int = 256  # answer bits (segments x runs) one drone may get
    run_window_s: float = 3600.0
    max_clock_skew_s: float = 30.0  # beacons and run requests further off our clock: refused
    run_timeout_s: float | None = 900.0  # a run's time limit (None: none)
    retry_after_s: float = 30.0
    busy_retry_s: tuple[float, float] = (5.0, 15.0)  # a peer busy with its own run: retry
    # after a random wait in this range (drones refused by one busy peer do not all return
    # at once)
    lookahead_s: float = 60.0  # the near run covers at least this much flight (0: no near run)
    cruise_m_s: float = 10.0  # MPC_XY_CRUISE: the flight model's speed until the mission's own
    failsafe: FailsafeSettings = field(default_factory=FailsafeSettings)
    separation: SeparationSettings = field(default_factory=SeparationSettings)


@dataclass(frozen=True)
class Credentials:
    """Who the companion is (its key and its operator's certificate), whom it deconflicts
    with (the trust store) and where it keeps what must survive a restart."""

    identity: Identity
    trust: TrustStore
    state_dir: Path


def mission_version(path: FlightPath, items: Sequence[MissionItem] = (), epoch: int = 0) -> int:
    """16-bit digest of the path in four dimensions: the ground track, the items' altitudes
    and the schedule's epoch (bumped when the drone falls behind or ahead of its windows)."""
    import hashlib

    flown = (path.points, [round(it.z, 2) for it in items], epoch)
    digest = hashlib.sha256(repr(flown).encode()).digest()
    return int.from_bytes(digest[:2], "big")


def same_track(a: list[MissionItem], b: list[MissionItem]) -> bool:
    """The same items in the same places (altitudes and the current mark aside)."""
    return len(a) == len(b) and all(
        (x.command, x.x, x.y, x.mission_type) == (y.command, y.x, y.y, y.mission_type)
        for x, y in zip(a, b, strict=True)
    )


def box_radius_m(
    path: list[tuple[int, int]], centre: tuple[int, int], minimum: float, room_m: float = 0.0
) -> float:
    """The comparison box's radius: ``minimum``, doubled until it holds the path with room
    to spare (the box's edge then stays clear of Alice's path by more than ``room_m``, the
    separation: Bob's path is cut to the box)."""
    extent = max((distance_m(centre, p) for p in path), default=0.0) * 1.1 + 50.0 + room_m
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
        autopilot: AutopilotBase,
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
        announced = keys_hash(self.boot, self.beacon_keys.public, public)  # (signed beacons)
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
        self.cadence = Cadence.of(endpoint.profile, settings.beacon_interval_s)
        self.sender = BeaconSender(
            settings.node,
            endpoint,
            self.identity,
            self.beacon_keys,
            announced,
            self.store,
            self.neighbours,
            self.cadence,
        )
        self._unknown_refused = -math.inf
        self._ignored: set[bytes] = set()  # untrusted drones logged already
        self._alerted: dict[int, float] = {}
        self._asking: dict[int, tuple[float, float]] = {}  # node -> (next ask, interval)
        self.rejected: dict[str, int] = {}  # beacons dropped, by reason
        self.holder_setups: dict[int, HolderSetup] = {}  # peer -> ours as Alice
        self.chooser_setups: dict[int, dict[bytes, ChooserSetup]] = {}  # peer -> ours as Bob
        self.peers: dict[int, Peer] = {}
        self.vehicle = VehicleState()  # what the autopilot's telemetry says
        self.events: list[Event] = []
        self.original: list[MissionItem] = []
        self.mission: list[MissionItem] = []
        self.home: tuple[int, int, float] | None = None  # lat, lon degE7, alt AMSL
        self.path = FlightPath(())  # the flown ground path of the original mission
        self.raises: dict[int, float] = {}  # segment -> metres higher, as uploaded
        self.edit: Edit | None = None  # the last verified upload (None: the original flies)
        self.retimed = 0  # the schedule's epoch: bumped when the drone leaves its windows
        self._timing: tuple[int, float, Schedule] | None = None  # (held mission, when, what)
        self._over_item: tuple[int, float] | None = None  # (current item, over it since)
        self._progress_seen: tuple[int, int, float] = (0, 0, 0.0)  # (current, of, when)
        self._planned: Schedule | None = None  # the original mission from the ground
        self._predictions: dict[
            tuple[object, ...], tuple[list[MissionItem], FlightPath, Schedule]
        ] = {}  # the last few schedules, by what they were predicted from
        self._slots_of: tuple[tuple[object, ...], Slots] | None = None  # (for what, slots)
        self._ground_since: float | None = None  # on the ground: since when its windows hold
        self._ground_retimes = 0  # ... and how often they were moved on there (each doubles)
        self.flagged: set[int] = set()  # segments the comparisons found in conflict
        self.precaution: dict[int, set[int]] = {}  # peer -> segments climbed as a precaution
        self._children: set[asyncio.Task[None]] = set()
        self._busy = asyncio.Lock()
        self._radio = RadioTurns()  # one run on the air at a time, as Alice or Bob
        self._edit_lock = asyncio.Lock()
        self._wake = asyncio.Event()
        self._sessions = 0  # runs on the air (as Alice or Bob)
        self._answering = 0  # runs we answer as Bob
        self._holding: set[int] = set()  # peers we hold for
        self._running: tuple[int, float] | None = None  # our run's peer, its expected end
        self._own_on_air: Alice | None = None  # our own run's machine while it holds the radio
        self._answers_waiting = 0  # admitted answers waiting for the radio (at most one)
        self._ground_wait: float | None = None  # since when a run waits for a quiet channel
        self.epoch = 0.0

    def record(self, kind: EventKind, payload: Payload) -> None:
        """An event at link seconds since :attr:`epoch` (the start, or the replay's zero),
        logged as ``key=value`` text and as a JSON line (:mod:`companion.app.logs`)."""
        event = Event(self.clock.now() - self.epoch, kind, payload)
        self.events.append(event)
        level = logging.WARNING if kind in WARNINGS else logging.INFO
        text = f"node {self.settings.node}: {kind.replace('_', ' ')}"
        logs.event(log, level, kind, text, t_s=round(event.t, 1), **event.detail)

    def _spawn(self, work: Coroutine[Any, Any, None], name: str = "child") -> asyncio.Task[None]:
        """A task of ours (:func:`companion.tasks.spawn`: a failure is logged with its
        traceback at once) whose failure the companion also records -- a companion whose
        beacons or answers died must say so, not go quiet; cancelled at :meth:`stop`."""
        task = spawn(
            work,
            name=f"node{self.settings.node}-{name}",
            log=log,
            on_failure=functools.partial(self._task_failed, name),
        )
        self._children.add(task)
        task.add_done_callback(self._children.discard)
        return task

    def _task_failed(self, name: str, exc: BaseException) -> None:
        self.record(EventKind.TASK_FAILED, TaskFailed(task=name, error=repr(exc)))

    @property
    def in_run(self) -> bool:
        """A run is on the air, as Alice or as Bob."""
        return self._sessions > 0

    @property
    def comparing(self) -> bool:
        """A comparison as Alice is under way, half done, or put off by a peer busy with its
        own (a drone about to take off waits for it); not one half done with a peer that has
        since gone out of range or fallen silent: it resumes if they meet again."""
        now = self.clock.now()
        return self._busy.locked() or any(
            (p.plan or p.busy or self._introducing(p, now))
            and self._pending(p)
            and not self._silent_for(p)
            for p in self.peers.values()
        )

    def _knows_us(self, peer: Peer) -> bool:
        """Its tagged beacons carry a tag for us: it holds our beacon key (it heard us)."""
        neighbour = self.neighbours.get(peer.node)
        return neighbour is not None and neighbour.knows_us

    def _introducing(self, peer: Peer, now: float) -> bool:
        """A peer we know that does not know us yet (it lacks our certificate or beacon
        key), met less than a signed-beacon period ago: the run waits for the introduction,
        and so does a take-off held for comparisons -- not for ever (a drone that does not
        trust us never will)."""
        return not self._knows_us(peer) and now - peer.met_at < self.cadence.signed_every_s

    @property
    def version(self) -> int:
        """What our beacons announce: the mission the vehicle holds, in four dimensions."""
        return mission_version(self.flown, self.mission, self.retimed)

    def _should_compare(self, peer: Peer, now: float) -> bool:
        """Pending, not waiting for a retry, and the peer can check our requests: its tagged
        beacons carry a tag for us (it holds our beacon key, so it heard us)."""
        return now >= peer.next_try and self._knows_us(peer) and self._pending(peer)

    def _pending(self, peer: Peer) -> bool:
        """We are Alice for this peer, it is in range, and its paths are not compared yet."""
        me = (self.vehicle.on_ground, self.settings.node)
        them = (peer.beacon.on_ground, peer.node)
        if peer.role is Role.BOB:
            return False
        if peer.role is None and alice_of(me, them) != self.settings.node:
            return False
        if self.settings.suite not in peer.beacon.suites:
            return False
        if self.vehicle.position[:2] == (0, 0):
            return False
        if distance_m(self.vehicle.position[:2], peer.position) > self.settings.initiation_range_m:
            return False
        return peer.compared != (peer.beacon.mission_version, self.compare_version)

    def _peer_speed(self, peer: Peer) -> float:
        """The speed the fail-safe assumes for a peer: its measured speed, at least the
        floor; an airborne peer not measured lately (heard too seldom, or silent since) may
        fly at cruise speed whatever it did when last measured."""
        floor = self.settings.failsafe.floor_m_s
        if not peer.beacon.on_ground and (not peer.measured or self._silent_for(peer) > 0):
            floor = max(floor, self.settings.cruise_m_s)
        return max(peer.speed_m_s, floor)

    def _silent_for(self, peer: Peer) -> float:
        """Seconds since the peer was last heard if it has fallen silent, else 0."""
        age = self.clock.now() - peer.heard_at
        return age if age > self.cadence.silence_s else 0.0

    def _still_heard(self, node: int) -> bool:
        """The peer has not fallen silent (:attr:`Cadence.silence_s`): a run's message the link
        gave up on goes again while it is heard -- a jammer, not a drone gone."""
        peer = self.peers.get(node)
        return peer is not None and not self._silent_for(peer)

    def _urgency(self, peer: Peer) -> float:
        return time_to_meet(
            self.vehicle.position[:2],
            self.vehicle.speed_m_s,
            peer,
            floor_m_s=self.settings.failsafe.floor_m_s,
            peer_floor_m_s=self._peer_speed(peer),
            now=self.clock.now(),
            silent_after_s=self.cadence.silence_s,
        )

    def _remaining_path(self) -> tuple[int, list[tuple[int, int]]]:
        """The path still to fly, of the *original* mission (what Alice compares: her edits
        are made on top of it)."""
        return self._remaining(self.path, self.original_current)

    def _remaining_flown(self) -> tuple[int, list[tuple[int, int]]]:
        """The path still to fly, of the mission the vehicle holds (what Bob answers with)."""
        return self._remaining(self.flown, self.vehicle.current_item)

    def _remaining(self, path: FlightPath, current: int) -> tuple[int, list[tuple[int, int]]]:
        """All of ``path`` before the first take-off; in flight from the leg to the current
        item; landed after flying, from there on -- and nothing (the landing point) once the
        current item is the last one on the path, so a drone whose mission is over never
        compares, as Alice, a path it will not fly again."""
        if self.vehicle.on_ground and not self.vehicle.has_flown:
            return 0, path.points
        start = path.start_at(current)
        points = path.points[start:]
        last = max((i for v in path.vertices for i in v.items), default=0)
        if self.vehicle.on_ground and current >= last:
            return len(path.points) - 1, points[-1:]
        return start, points

    @property
    def original_current(self) -> int:
        """The vehicle's current item as an item of the original mission."""
        if self.edit is None:
            return self.vehicle.current_item
        origin = self.edit.origin
        return origin[min(max(self.vehicle.current_item, 0), len(origin) - 1)] if origin else 0

    @property
    def flown(self) -> FlightPath:
        """The flown ground path of the mission the vehicle holds (an inserted waypoint
        is a vertex of its own)."""
        if self.edit is None or self.edit.inserted is None:
            return self.path
        home = None if self.home is None else self.home[:2]
        return flight_path(self.mission, home, ardupilot=self.settings.ardupilot)

    @property
    def compare_version(self) -> int:
        """The version of what we compare as Alice (the original mission, on our schedule)."""
        return mission_version(self.path, self.original, self.retimed)

    @property
    def kinematics(self) -> Kinematics:
        return Kinematics(cruise_m_s=self.settings.cruise_m_s)

    def _home_deg(self) -> tuple[float, float, float]:
        """Home (degrees, metres AMSL): PX4's HOME_POSITION, ArduPilot's item 0, or else
        where the vehicle is, at the altitude its relative altitude counts from."""
        if self.home is not None:
            return self.home[0] / 1e7, self.home[1] / 1e7, self.home[2]
        if self.settings.ardupilot and self.mission:
            first = self.mission[0]
            return first.x / 1e7, first.y / 1e7, first.z
        lat, lon, alt = self.vehicle.position
        return lat / 1e7, lon / 1e7, alt - self.vehicle.relative_alt

    def _schedule(
        self,
        items: list[MissionItem],
        path: FlightPath,
        start: int,
        current: int,
        limit_s: float = MAX_PREDICTION_S,
    ) -> Schedule:
        """``path`` (the flown path of ``items``) in four dimensions from vertex ``start``,
        as the flight model flies ``items`` on from where the vehicle is now."""
        home = self._home_deg()
        lat, lon = self.vehicle.position[0] / 1e7, self.vehicle.position[1] / 1e7
        if self.vehicle.position[:2] == (0, 0):
            lat, lon = home[0], home[1]
        loitering = 0.0
        if self._over_item is not None and self._over_item[0] == self.vehicle.current_item:
            loitering = self.vehicle.position_at - self._over_item[1]
        vehicle = Vehicle(
            lat,
            lon,
            self.vehicle.relative_alt,
            self.vehicle.speed_m_s,
            current,
            self.vehicle.on_ground,
            loitering,
            self.vehicle.climb_m_s,
            self.vehicle.held and not self.vehicle.on_ground,
            self._ground_wait_left(),
        )
        # The same prediction is asked for again and again between two telemetry samples
        # (a run's plan, its volumes, the fail-safe): flown once per vehicle state.
        key = (id(items), id(path), home, start, vehicle, limit_s)
        hit = self._predictions.get(key)
        if hit is not None and hit[0] is items and hit[1] is path:
            return hit[2]
        schedule = predict(
            path,
            items,
            home,
            start,
            vehicle,
            self.kinematics,
            home_is_item0=self.settings.ardupilot,
            limit_s=limit_s,
        )
        self._predictions[key] = (items, path, schedule)
        while len(self._predictions) > PREDICTIONS_KEPT:
            self._predictions.pop(next(iter(self._predictions)))
        return schedule

    def _ground_allowance(self) -> float:
        """How long a drone on the ground is assumed to wait before it takes off, counted
        from :attr:`_ground_since`: the tolerance's, doubled at each move on the ground."""
        return self.settings.separation.tolerance.ground_wait_s * 2.0**self._ground_retimes

    def _ground_wait_left(self) -> float:
        """On the ground: how much longer it may wait before it takes off and still fly
        within the windows its peers hold (infinite: not on the ground -- or more than half
        the wait is over and :meth:`_keep_time` has not moved it on yet: then when it takes
        off is not known)."""
        if not self.vehicle.on_ground or self.vehicle.has_flown:
            return math.inf
        now = self.clock.now()
        if self._ground_since is None:
            self._ground_since = now
        left = self._ground_since + self._ground_allowance() - now
        return left if left >= self._ground_allowance() / 2 else math.inf

    def _wall_of_state(self) -> float:
        """The wall time of the vehicle state predictions start from (its last position)."""
        if self.vehicle.position_at == 0.0:
            return self.clock.wall()
        return self.clock.wall() - (self.clock.now() - self.vehicle.position_at)

    def _note_position(self) -> None:
        """Since when the vehicle has been over its current item's point (a loiter's or a
        waypoint's hold time under way, which the schedule counts down from there)."""
        i = self.vehicle.current_item
        item = (
            self.mission[i] if not self.vehicle.on_ground and 0 <= i < len(self.mission) else None
        )
        if (
            item is None
            or item.command not in (NAV_LOITER_TIME, NAV_WAYPOINT)
            or not item.has_position
            or distance_m(self.vehicle.position[:2], (item.x, item.y)) > OVER_ITEM_M
        ):
            self._over_item = None
        elif self._over_item is None or self._over_item[0] != i:
            self._over_item = (i, self.vehicle.position_at)

    def _keep_time(self) -> None:
        """Compare again when the vehicle has left the windows it announced: against the
        schedule predicted at take-off, at the last edit or the last re-timing, a short
        prediction from where it is now shows whether it is off by half the tolerance
        (:func:`companion.mission.schedule.off_schedule`); then the schedule's epoch (part of our
        version) moves on and every peer is due a run again.  On the ground the windows
        assume a take-off within a wait (:meth:`_ground_allowance`): once half of it has passed
        with the drone still there, they move on, the wait doubled.  The paper suite has no
        windows: nothing to keep."""
        if self._edit_lock.locked():  # the mission and its current item are changing
            return
        if not self.vehicle.on_ground or self.vehicle.has_flown:  # (landed: its mission is over)
            self._ground_since, self._ground_retimes = None, 0
        elif self.settings.suite is Suite.COMPACT:
            now = self.clock.now()
            if self._ground_since is None:
                self._ground_since = now
            elif now - self._ground_since > self._ground_allowance() / 2:
                self._ground_since = now
                self._ground_retimes += 1
                self._retime(0.0, ground=True)
        if (
            self.vehicle.held
            and not self.vehicle.on_ground
            and self.settings.suite is Suite.COMPACT
        ):
            # Holding: when it flies on is unknown, its windows are open to the end from now
            # on (as on the ground).  Once, when the hold begins, its peers compare again.
            if self._timing is not None:
                self._timing = None
                self._retime(0.0)
            return
        if (
            self.vehicle.on_ground
            or self.vehicle.relative_alt < 1.0
            or self.settings.suite is not Suite.COMPACT
        ):
            self._timing = None  # (armed on the ground: the spool-up's length is unknown)
            return
        start, points = self._remaining_flown()
        if len(points) < 2:
            return
        key = mission_version(self.flown, self.mission)
        now = self.vehicle.position_at  # the predictions start from the vehicle's state then
        if self._timing is None or self._timing[0] != key:
            full = self._schedule(self.mission, self.flown, start, self.vehicle.current_item)
            self._timing = (key, now, full)
            return
        _, then, before = self._timing
        soon = self._schedule(
            self.mission, self.flown, start, self.vehicle.current_item, limit_s=TIMING_LOOK_S
        )
        drift = off_schedule(before, then, soon, now, self.settings.separation.tolerance)
        if drift is None:
            return
        full = self._schedule(self.mission, self.flown, start, self.vehicle.current_item)
        self._timing = (key, now, full)
        self._retime(drift)

    def _retime(self, drift: float, *, ground: bool = False) -> None:
        """Our windows moved (``drift`` seconds late; 0: a hold began, they are open to the
        end; ``ground``: still on the ground after half its wait): a new schedule epoch, a
        new version, every peer compares again."""
        self.retimed += 1
        self.record(
            EventKind.RETIMED,
            Retimed(
                epoch=self.retimed,
                drift_s=round(drift, 1),
                held=drift == 0.0 and not ground,
                on_ground=ground,
            ),
        )
        self.sender.announce()

    def _peer_pace(self, peer: Peer) -> float:
        """How fast the peer may fly through the path it showed: its speed, at least cruise."""
        return max(self._peer_speed(peer), self.settings.cruise_m_s)

    def _near_expires(self, peer: Peer) -> float:
        """When the peer may be past the path its last near run showed (its horizon at
        :meth:`_peer_pace` from the run's start); -inf without a near run."""
        if peer.near_run is None:
            return -math.inf
        started, horizon = peer.near_run
        return started + horizon / self._peer_pace(peer)

    def _decided(self, peer: Peer) -> set[int]:
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
        beyond = self._near_expires(peer) - self.clock.now() - self.settings.failsafe.margin_s
        if self.vehicle.on_ground and not self.vehicle.has_flown:
            return decided  # (take-off time unknown: windows never close)
        start = self._remaining_path()[0]
        decided |= {k for k in near if k < start}  # flown already
        near = {k for k in near if k >= start}
        if not near:
            return decided
        schedule = self._schedule(self.original, self.path, start, self.original_current)
        tolerance = self.settings.separation.tolerance
        for k in near:
            try:
                if schedule.window(k, tolerance)[1] < beyond:
                    decided.add(k)
            except IndexError:  # beyond the scheduled path
                continue
        return decided

    def _volumes(self, grid: GridSpec, epoch_s: int = 0) -> VolumeSpec:
        """The volume parameters of our runs on ``grid`` (the compact suite's; the paper
        suite compares the crossing only)."""
        if self.settings.suite is not Suite.COMPACT:
            return CROSSING
        return run_volumes(self.settings.separation, grid.resolution_mm, epoch_s)

    def _own_size(self) -> int:
        """Our remaining path's padded size (our beacons' size class; as Bob, at most n)."""
        _, path = self._remaining_path()
        return DEFAULT_LIMITS.public_size(len(path) - 1)

    def _slots(self) -> Slots:
        """The altitude slots the rest of our flight occupies, as the vehicle flies it.  They
        change with the mission, the item flown to and the altitude the vehicle is at (to
        the metre: a slot is 5 m), not with each position report: remembered for those."""
        start, points = self._remaining_flown()
        if len(points) < 2:
            return Slots.of([(self.vehicle.position[2], self.vehicle.position[2])])
        key = (
            self.version,
            self.vehicle.current_item,
            self.vehicle.on_ground,
            round(self.vehicle.relative_alt),
        )
        if self._slots_of is not None and self._slots_of[0] == key:
            return self._slots_of[1]
        schedule = self._schedule(self.mission, self.flown, start, self.vehicle.current_item)
        tolerance = self.settings.separation.tolerance
        slots = Slots.of(
            schedule.cruise(k, tolerance) for k in range(start, start + len(points) - 1)
        )
        self._slots_of = (key, slots)
        return slots

    def _grid(self, path: list[tuple[int, int]]) -> GridSpec:
        lat, lon = self.vehicle.position[:2]
        radius = box_radius_m(
            path, (lat, lon), self.settings.grid_radius_m, self.settings.separation.horizontal_m
        )
        return GridSpec.geo(
            lat, lon, resolution_mm=self.settings.grid_resolution_mm, radius_m=radius
        )

    def _seconds(
        self,
        m: int,
        grid: GridSpec,
        *,
        fresh: bool,
        n: int | None = None,
        skip: int = 0,
        stall_loss: float | None = None,
    ) -> float:
        """Link seconds an m x n run (n unknown: Bob's size taken as Alice's) will need from
        now, its first ``skip`` messages already exchanged (``stall_loss``: see
        :func:`~companion.runs.failsafe.run_seconds`)."""
        if self.settings.suite is not Suite.COMPACT:
            return 0.0
        sizes = message_sizes(
            m,
            m if n is None else n,
            grid,
            fresh_setup=fresh,
            ot_security=self.settings.ot_security,
            volumes=self._volumes(grid),
        )[skip:]
        return run_seconds(
            sizes,
            self.endpoint.profile,
            loss=self.settings.failsafe.loss,
            duty=self.endpoint.duty,
            now=self.clock.now(),
            stall_loss=stall_loss,
        )

    def _near(self, path: list[tuple[int, int]], horizon: int) -> list[tuple[int, int]]:
        """The part of the remaining path a run with this horizon compares (a full run's
        horizon is 0: all of it)."""
        return near_cut(path, horizon, self.vehicle.here(), least=NEAR_SEGMENTS)

    def _forget(self, node: int) -> None:
        self.peers.pop(node, None)
        self._drop_setups(node)

    def _drop_setups(self, node: int) -> None:
        """The OT setups we share with ``node`` (both roles)."""
        self.holder_setups.pop(node, None)
        self.chooser_setups.pop(node, None)
