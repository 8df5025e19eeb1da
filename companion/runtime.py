"""The companion process: beacons, peers, private comparisons and altitude edits.

One :class:`Companion` per drone, beside its autopilot.  It beacons its coarse position; when
it hears a peer within the initiation range, the role rule (:func:`companion.beacon.alice_of`)
picks exactly one of the two as Alice.  Alice compares the part of her mission still to fly
with the peer's through the private protocol over the radio; the peer (Bob) answers with the
part of *his* mission still to fly and learns nothing.  Alice flies her conflicting segments
at an altitude level (:mod:`companion.levels`), uploads the edit and reads it back.

In flight, what can be reached soon is compared first: a *near* run on the next
``lookahead_s`` seconds of both paths, then the *full* run on the rest.  The most urgent peer
(the one that could be here first) is served first.  Before and during every run Alice checks
that the result can arrive in time (:mod:`companion.failsafe`); if not, she takes the
precautionary action (climb over, or hold before, the segments within the peer's reach) until
the result is in.  The OT setup with each peer is made once and cached.  Runs per peer are
limited (probing mitigation); failures are recorded, leave the mission as it was, and never
stop the process from serving other peers: nothing raises out of a run.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import logging
import math
import random
import secrets
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.errors import ProtocolError
from protocol.grid import GridSpec
from protocol.intersection import MAX_SEGMENTS, Alice, Bob, BobKeys, Limits, State
from protocol.ot.setup import DEFAULT_SECURITY, ChooserSetup, HolderSetup
from protocol.suite_compact import message_sizes
from protocol.wire import Hello, Suite

from . import logs
from .auth.beacon_keys import BeaconKeys
from .auth.certificate import Certificate
from .auth.session import (
    BOOT_SIZE,
    AuthenticationError,
    Identity,
    Init,
    Initiator,
    Refusal,
    Responder,
    Route,
)
from .auth.trust import TrustStore, UnknownPeers
from .autopilot import Autopilot, AutopilotError
from .beacon import (
    MAX_SIZE_CLASS,
    Beacon,
    CertBeacon,
    alice_of,
    keys_hash,
    size_class,
)
from .beacon_budget import beacon_interval
from .budget import ALICE, BOB, BudgetExceeded, RunLedger, RunLimits
from .events import WARNINGS, Event, EventKind
from .exchange import PeerRefused, run_alice, serve_bob
from .failsafe import Action, FailsafeSettings, at_risk, run_seconds, too_late
from .flightpath import FlightPath, flight_path
from .levels import levels_mask, plan_levels
from .link.arq import LinkError
from .link.endpoint import LinkEndpoint
from .link.frames import AbortCode
from .mission import MissionError, MissionItem, point_as_segment
from .neighbours import NO_CERTIFICATE, Heard, Hearing, Neighbour, Neighbours
from .peers import FRESH_S, Peer, distance_m, near_cut, time_to_meet
from .planner import OffsetSettings, PlannerError, fixed_segments, plan_offsets
from .progress import RunProgress
from .radio import ANSWER_FULL, ANSWER_NEAR, OWN_FULL, OWN_NEAR, RadioTurns
from .roles import Role
from .state import OWN, StateStore

log = logging.getLogger("companion")
_JITTER = random.SystemRandom()
SETUPS_PER_PEER = 2
POSITION_RATE_HZ = 5.0  # telemetry position updates asked of the autopilot
NEAR_SLACK_S = 30.0  # the near run reaches this far past the earliest possible meeting
NEAR_SEGMENTS = 2  # and each side compares at least its next two segments
BOB_GUESS = 4  # Bob's size before he tells it: a remaining route of a few legs (m x m would
# stretch the horizon of a long route over everything; the run watch uses his real size)
QUIET_S = 5.0  # no session traffic heard this long: the channel is free for a full run
GROUND_WAIT_S = 60.0  # on the ground, a run waits this long at most for a quiet channel
SIGNED_EVERY_S = 300.0  # a signed beacon at least this often (for drones that missed one),
SIGNED_EVERY = 30  # and at most every 30th beacon (a duty cycle stretches beacons to minutes)
ASKED_AGAIN = 0.5  # asked for, a certificate or signed beacon at most every half interval
AUTOPILOT_SILENT_S = 5.0  # no position from the autopilot this long (real s): a warning
ALERT_EVERY_S = 60.0  # an untrusted drone is reported at most this often (policy "alert")


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
    max_runs_per_peer: int = 8  # runs a certified drone may ask of us per window
    max_runs_total: int = 64  # runs all peers together may ask of us per window
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


class Companion:
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
            RunLimits(settings.max_runs_per_peer, settings.max_runs_total, settings.run_window_s),
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

    # ------------------------------------------------------------------ lifecycle

    def record(self, kind: EventKind, **detail: Any) -> None:
        """An event at link seconds since :attr:`epoch` (the start, or the replay's zero),
        logged as ``key=value`` text and as a JSON line (:mod:`companion.logs`)."""
        t = self.clock.now() - self.epoch
        self.events.append(Event(t, kind, detail))
        level = logging.WARNING if kind in WARNINGS else logging.INFO
        text = f"node {self.settings.node}: {kind.replace('_', ' ')}"
        logs.event(log, level, kind, text, t_s=round(t, 1), **detail)

    async def start(self) -> None:
        self.epoch = self.clock.now()
        self.original = await self.autopilot.download()
        self.mission = list(self.original)
        if not self.settings.ardupilot:  # ArduPilot's home is item 0 of the mission
            self.home = await self.autopilot.home()
        home = None if self.home is None else self.home[:2]
        try:
            self.path = flight_path(self.mission, home, ardupilot=self.settings.ardupilot)
        except MissionError as exc:  # e.g. a DO_JUMP to nowhere: fly, but compare nothing
            self.record(EventKind.MISSION_INVALID, error=str(exc))
        self.record(
            EventKind.MISSION,
            items=len(self.mission),
            segments=self.path.segments,
            home=self.home is not None or self.settings.ardupilot,
        )
        await self.endpoint.start()
        self._tasks = [
            asyncio.create_task(self._telemetry(), name="telemetry"),
            asyncio.create_task(self._progress(), name="progress"),
            asyncio.create_task(self._autopilot_watch(), name="autopilot watch"),
            asyncio.create_task(self._certificates(), name="certificates"),
            asyncio.create_task(self._beacons(), name="beacons"),
            asyncio.create_task(self._listen(), name="listen"),
            asyncio.create_task(self._serve(), name="serve"),
            asyncio.create_task(self._alice_loop(), name="alice"),
            asyncio.create_task(self._guard(), name="guard"),
        ]
        for task in self._tasks:
            task.add_done_callback(self._ended)

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

    async def stop(self) -> None:
        for task in [*self._tasks, *self._children]:
            task.cancel()
        for task in [*self._tasks, *self._children]:
            with contextlib.suppress(asyncio.CancelledError):
                try:  # bounded: a stop never hangs on one task
                    await asyncio.wait_for(asyncio.shield(task), 5.0)
                except TimeoutError:
                    log.warning("node %d: task %s did not stop", self.settings.node, task)
                except Exception as exc:  # a task that failed has nothing left to stop
                    log.warning("node %d: task %s ended with %r", self.settings.node, task, exc)
        await self.endpoint.close()
        self.store.close()

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

    # ------------------------------------------------------------------ vehicle state

    async def _telemetry(self) -> None:
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry = TelemetryAsync(self.autopilot.system)
        last: tuple[float, tuple[int, int]] | None = None
        try:
            # PX4 sends GLOBAL_POSITION_INT at 50 Hz on the onboard link (500 Hz in SITL at
            # 10x); a few per second is plenty here and keeps MAVSDK's callbacks keeping up
            try:
                await asyncio.wait_for(telemetry.set_rate_position(POSITION_RATE_HZ), 5.0)
            except Exception as exc:  # any MAVSDK error: keep the default rate
                log.info("position rate unchanged: %s", exc)
            async for p in telemetry.subscribe_position():
                self._heard_autopilot = time.monotonic()
                self.position = (
                    round(p.latitude_deg * 1e7),
                    round(p.longitude_deg * 1e7),
                    float(p.absolute_altitude_m),
                )
                was_on_ground = self.on_ground
                self.relative_alt = float(p.relative_altitude_m)
                if was_on_ground and not self.on_ground:
                    self.has_flown = True
                    self._beacon_now.set()  # taking off: announce it
                now = self.clock.now()
                if last is None or now - last[0] >= 1.0:
                    if last is not None:
                        moved = distance_m(last[1], self.position[:2]) / (now - last[0])
                        self.speed_m_s = 0.5 * (self.speed_m_s + moved)
                    last = (now, self.position[:2])
        finally:
            telemetry.destroy()

    async def _autopilot_watch(self) -> None:
        """Warn when the autopilot's position stops coming (real seconds: MAVLink streams run
        in real time whatever the link's clock), and again when it is back."""
        silent = False
        while True:
            await asyncio.sleep(1.0)
            gap = time.monotonic() - self._heard_autopilot
            if gap >= AUTOPILOT_SILENT_S and not silent:
                silent = True
                logs.event(
                    log,
                    logging.WARNING,
                    "autopilot_silent",
                    f"node {self.settings.node}: no position from the autopilot for {gap:.0f} s",
                    url=self.settings.autopilot_url,
                )
            elif gap < AUTOPILOT_SILENT_S and silent:
                silent = False
                log.info("node %d: the autopilot's position is back", self.settings.node)

    async def _progress(self) -> None:
        async for progress in self.autopilot.mission_raw.subscribe_mission_progress():
            self.current_item = int(progress.current)

    # ------------------------------------------------------------------ radio

    def _stamp(self) -> tuple[int, int]:
        """(time, counter) of our next beacon: together they only ever grow, also across
        restarts (the last pair is kept on disk), so a peer never takes a fresh beacon of
        ours for a replay."""
        now = int(self.clock.wall()) << 8
        if self._order is None:  # the first beacon of this start
            self._order = self.store.last_counter(OWN) or 0
        self._order = max(self._order + 1, now)
        self.store.set_counter(OWN, self._order)
        return self._order >> 8, self._order & 0xFF

    def _beacon(self) -> tuple[bytes, str]:
        """Our position beacon (:mod:`companion.beacon`): signed when one is due (it carries
        our beacon key and keys hash), else tagged for every neighbour we share a key with."""
        lat, lon, alt = self.position
        _, path = self._remaining_path()
        segments = Limits().padded(min(max(len(path) - 1, 1), MAX_SEGMENTS))
        time_s, counter = self._stamp()
        beacon = Beacon(
            lat,
            lon,
            round(alt),
            self.on_ground,
            frozenset({self.settings.suite}),
            self.version,
            time_s,
            counter,
            levels_mask(self.levels),
            size_class(segments),
        )
        now = self.clock.now()
        tags = self.neighbours.tag_keys(self.clock.wall() - self._silence_s)
        if self._sign_next or now - self._signed_at >= self._signed_every_s:
            self._sign_next, self._signed_at = False, now
            signed = beacon.signed(
                self.settings.node, self.identity.key, self.beacon_keys.public, self.keys_hash, tags
            )
            return signed, "signed"
        return beacon.tagged(self.settings.node, tags), "tagged"

    def _want_signed(self) -> None:
        """A signed beacon next (rate-limited): somebody lacks our beacon key."""
        if self.clock.now() - self._signed_at >= self._asked_every_s:
            self._sign_next = True
            self._beacon_now.set()

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

    async def _send_beacon(self, payload: bytes, kind: str) -> None:
        with contextlib.suppress(LinkError):
            await self.endpoint.beacon(payload)
            self.beacon_bytes += len(payload)
            self.beacons_sent[kind] += 1

    async def _certificates(self) -> None:
        """Our certificate beacon: at the start, when we hear a drone we cannot check yet
        (asking for its certificate and signed beacon: WANT) and when a peer asks for ours --
        at most every half a beacon interval (a stranger's made-up beacons cost us at most
        that)."""
        while True:
            await self._cert_now.wait()
            wait = self._cert_sent + self._asked_every_s - self.clock.now()
            # an answer right after the question would meet the asker's next frame
            await self.clock.sleep(max(wait, 0.0) + _JITTER.uniform(0.1, 1.0))
            self._cert_now.clear()
            want, self._cert_wanted = self._cert_wanted, False
            self._cert_sent = self.clock.now()
            await self._send_beacon(CertBeacon(self.identity.cert, want).encode(), "certificate")

    async def _beacons(self) -> None:
        """Beacon every interval (random phase and jitter: drones that beacon in lockstep
        collide on every beacon), and at once when the drone takes off or hears a new peer
        -- on a duty-cycled link the interval is minutes, discovery must not wait for it."""
        wait = _JITTER.uniform(0, self.beacon_interval)
        deferred = 0
        while True:
            with contextlib.suppress(TimeoutError):
                await self.clock.wait_for(self._beacon_now.wait(), wait)
            urgent = self._beacon_now.is_set()
            if urgent:
                self._beacon_now.clear()
                await self.clock.sleep(_JITTER.uniform(0.0, 1.0))  # do not answer in chorus
            if (self._sessions or self.endpoint.busy()) and not urgent and deferred < 3:
                # A run is on the air: a beacon would only collide with its frames.
                deferred += 1
            elif self.position[:2] != (0, 0):
                deferred = 0
                await self._send_beacon(*self._beacon())
            wait = self.beacon_interval * _JITTER.uniform(0.7, 1.3)

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
                self._cert_wanted = True
                self._cert_now.set()
            # Its beacon key or its tag for us is missing: with our signed beacon it gets our
            # key (and tags for us), and it answers a new key with its own signed beacon.
            self._want_signed()
            return
        if hearing.kind is Heard.UNTRUSTED:
            self._untrusted(hearing)
            return
        if hearing.kind is Heard.CERTIFICATE:
            if hearing.want:  # it cannot check somebody's beacons: ours, perhaps
                self._cert_now.set()
                self._want_signed()
            if hearing.then is not None:  # its signed beacon, heard before the certificate
                self._heard(hearing.then)
            return
        beacon, neighbour = hearing.beacon, hearing.neighbour
        assert beacon is not None and neighbour is not None
        if neighbour.knows_us:
            self._asking.pop(src, None)  # nothing to ask it for any more
        if hearing.new_keys:  # a new beacon key: it may lack ours
            self._want_signed()
        now = self.clock.now()
        peer = self.peers.get(src)
        if peer is not None and peer.identity != neighbour.fingerprint:
            self._forget(src)  # another drone holds this node id now
            peer = None
        if peer is None:
            peer = self.peers[src] = Peer(src, beacon, now, identity=neighbour.fingerprint)
            self.record(
                EventKind.PEER,
                peer=src,
                on_ground=beacon.on_ground,
                drone=neighbour.fingerprint.hex(),
                operator=neighbour.operator.name,
            )
            self._beacon_now.set()  # let it hear us without waiting an interval
        elif hearing.new_keys:
            self._drop_setups(src)  # it restarted (a new beacon key): they are gone on its side
        levels_changed = peer.beacon.levels != beacon.levels
        peer.heard(beacon, now, self.position[:2])
        if levels_changed and (peer.conflicts or src in self.precaution):
            self._spawn(self._replan(f"peer {src} announced levels {beacon.levels:#04x}"))
        self._wake.set()

    def _may_ask(self, node: int) -> bool:
        """Whether to ask again for what a node's beacons lack (its certificate, or its tag for
        us): at once the first time, then less and less often (to 5 minutes) while it stays
        so -- a drone that does not trust us would otherwise make us ask forever."""
        now = self.clock.now()
        due, interval = self._asking.get(node, (now, self._asked_every_s / 2))
        if now < due:
            return False
        interval = min(2 * interval, self._signed_every_s)
        self._asking[node] = (now + interval, interval)
        return True

    def _forget(self, node: int) -> None:
        self.peers.pop(node, None)
        self._drop_setups(node)

    def _drop_setups(self, node: int) -> None:
        """The OT setups we share with ``node`` (both roles)."""
        self.holder_setups.pop(node, None)
        self.chooser_setups.pop(node, None)

    def _untrusted(self, hearing: Hearing) -> None:
        """A drone the trust store does not accept: never deconflicted with; logged once, and
        with policy ``alert`` reported as an intruder (at most every ALERT_EVERY_S)."""
        assert hearing.cert is not None  # an untrusted drone is one whose certificate we refused
        drone = hearing.cert.fingerprint
        if drone not in self._ignored:
            self._ignored.add(drone)
            self.record(
                EventKind.UNTRUSTED, peer=hearing.node, drone=drone.hex(), reason=hearing.reason
            )
        if self.neighbours.trust.unknown is not UnknownPeers.ALERT or hearing.beacon is None:
            return
        now = self.clock.now()
        if now - self._alerted.get(hearing.node, -math.inf) >= ALERT_EVERY_S:
            self._alerted[hearing.node] = now
            b = hearing.beacon
            distance = distance_m(self.position[:2], (b.lat, b.lon))
            self.record(
                EventKind.INTRUDER, peer=hearing.node, drone=drone.hex(), lat=b.lat, lon=b.lon,
                alt_m_amsl=b.alt_m, distance_m=round(distance),
            )  # fmt: skip

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

    # ------------------------------------------------------------------ Alice

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

    def _grid(self, path: list[tuple[int, int]]) -> GridSpec:
        lat, lon = self.position[:2]
        radius = box_radius_m(path, (lat, lon), self.settings.grid_radius_m)
        return GridSpec.geo(
            lat, lon, resolution_mm=self.settings.grid_resolution_mm, radius_m=radius
        )

    def _here(self) -> tuple[int, int] | None:
        """Where the drone is, for distances along its path (None on the ground)."""
        return None if self.on_ground or self.position[:2] == (0, 0) else self.position[:2]

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
                self.record(
                    EventKind.RUN_FAILED, peer=peer.node, phase=phase, refused=exc.code.name
                )
                return False
            except AuthenticationError as exc:
                self.record(EventKind.RUN_FAILED, peer=peer.node, phase=phase, auth=str(exc))
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

    async def _watch(
        self,
        peer: Peer,
        alice: Alice,
        grid: GridSpec,
        needed: float,
    ) -> None:
        """While a run is under way: act as soon as its result could come too late.  Until
        Bob's first reply tells his size the estimate is that of the smallest Bob (Alice's
        own size would cry wolf when Bob's path is short: runs are sized m x n); then it is
        the rest of the real m x n run from that moment; past it, as long as the overrun."""
        deadline = self.clock.now() + needed
        self._running = (peer.node, deadline)
        sized = False
        while True:
            await self.clock.sleep(2.0)
            if not sized and alice.n is not None:
                sized = True  # messages 1 and 2 (hello, offer) are behind us
                rest = self._seconds(alice.m, grid, fresh=False, n=alice.n, skip=2)
                deadline = self.clock.now() + rest
                self._running = (peer.node, deadline)
            # Overdue (losses, a silent peer): the estimate has failed; expect as long again
            # as it has overrun, so the fail-safe does not wait for the last seconds.
            left = max(abs(deadline - self.clock.now()), 2.0)
            if too_late(left, self._urgency(peer), self.settings.failsafe):
                await self._precaution(peer, left, self._urgency(peer))
                return

    async def _guard(self) -> None:
        """The fail-safe for peers still waiting for their run (one run at a time on the
        radio, a retry after a failure): act when even the smallest run, started once ours
        on the air ends, would bring the result too late.  The peer a run is under way with
        has its own watch."""
        while True:
            await self.clock.sleep(2.0)
            if self.on_ground or not self.peers:
                continue
            now = self.clock.now()
            running, ends = self._running or (None, now)
            for peer in list(self.peers.values()):
                if peer.node == running or peer.node in self.precaution or not self._pending(peer):
                    continue
                _, path = self._remaining_path()
                if len(path) < 2:
                    break
                first = self._near(path, 1)  # the least a run compares
                needed = max(ends - now, 0.0) + self._seconds(
                    Limits().padded(len(first) - 1),
                    self._grid(first),
                    fresh=peer.node not in self.holder_setups,
                    n=1,
                )
                meet = self._urgency(peer)
                if too_late(needed, meet, self.settings.failsafe):
                    await self._precaution(peer, needed, meet, waiting=True)

    async def _precaution(
        self, peer: Peer, needed: float, meet: float, *, waiting: bool = False
    ) -> None:
        """Climb over (or hold before) the segments both drones may reach before the result.
        The path is what is left to fly *now*: a run's path starts where the drone was when
        it began, and distances from here along legs already flown would come out wrong."""
        settings = self.settings.failsafe
        if peer.node in self.precaution or peer.node in self._holding or self.on_ground:
            return  # (on the ground the drone waits for its comparisons anyway)
        start, path = self._remaining_path()
        speed = max(self.speed_m_s, self.settings.cruise_m_s)
        risky = at_risk(
            path, start, self._here(), speed, peer.position, self._peer_speed(peer), needed,
            settings, peer.covered, peer_age_s=self._silent_for(peer),
        )  # fmt: skip
        if not risky:
            return
        self.record(
            EventKind.PRECAUTIONARY,
            peer=peer.node,
            action=settings.action.value,
            segments=risky,
            first_segment=start,
            needed_s=round(needed, 1),
            time_to_meet_s=round(meet, 1) if math.isfinite(meet) else None,
            waiting=waiting,  # no run under way with this peer yet (queued, or a retry)
        )
        if settings.action is Action.OFF:
            self.precaution[peer.node] = set()  # reported once; nothing flies differently
            return
        if settings.action is Action.CLIMB:
            self.precaution[peer.node] = set(risky)  # levels chosen with the conflicts
            await self._replan(f"precaution for {peer.node}")
        else:
            self._holding.add(peer.node)
            self._spawn(self._hold_before(peer.node, risky[0]))

    async def _hold_before(self, peer: int, segment: int) -> None:
        """Pause the mission once the vehicle reaches the start of ``segment``."""
        vs = self.path.vertices
        end = vs[min(segment + 1, len(vs) - 1)]
        gate = min(end.items, default=0)  # the segment is flown once its end item is current
        while peer in self._holding and self.current_item < gate:
            await self.clock.sleep(0.5)
        if peer not in self._holding:
            return
        try:
            await self.autopilot.pause()
            self.record(EventKind.HOLD, peer=peer, before_segment=segment)
        except AutopilotError as exc:
            self.record(EventKind.HOLD_FAILED, peer=peer, error=str(exc))

    async def _release(self, peer: Peer) -> None:
        """The result is in: precautions for this peer end."""
        self.precaution.pop(peer.node, None)
        if peer.node in self._holding:
            self._holding.discard(peer.node)
            if not self._holding:
                try:
                    await self.autopilot.resume()
                    self.record(EventKind.RESUMED, peer=peer.node)
                except AutopilotError as exc:
                    self.record(EventKind.RESUME_FAILED, peer=peer.node, error=str(exc))

    async def _replan(self, why: str) -> None:
        """Upload the altitude levels the conflicts and precautions call for, if they changed."""
        async with self._edit_lock:
            levels = plan_levels(
                {node: p.conflicts for node, p in self.peers.items()},
                self.precaution,
                {node: p.beacon.levels for node, p in self.peers.items()},
            )
            if levels == self.levels:
                return
            try:
                planned = plan_offsets(self.original, levels, self.settings.offset, path=self.path)
            except PlannerError as exc:
                self.record(EventKind.PLAN_FAILED, error=str(exc))
                return
            fixed = fixed_segments(self.path, levels)
            if fixed:  # e.g. the launch leg to a take-off point: nothing there may move
                self.record(EventKind.FIXED_SEGMENTS, segments=fixed, why=why)
            try:
                # The edit is built on what the vehicle holds now and keeps the item it is
                # flying: PX4 restarts a mission at the item an upload marks current.
                held = await self.autopilot.download()
                if not same_track(held, self.original):
                    raise AutopilotError("the vehicle's mission changed since the start")
                current = max(
                    self.current_item, next((i for i, it in enumerate(held) if it.current), 0)
                )
                current = min(current, len(held) - 1)
                new = [
                    h.replace(z=p.z, current=int(i == current))
                    for i, (h, p) in enumerate(zip(held, planned, strict=True))
                ]
                await self.autopilot.replace_mission(new, held)
            except (AutopilotError, MissionError) as exc:
                self.record(EventKind.UPLOAD_FAILED, error=str(exc))
                return
            announce = levels_mask(levels) != levels_mask(self.levels)
            self.mission, self.levels = new, levels
            if announce:  # peers choose their levels around ours: tell them now, not in
                self._beacon_now.set()  # minutes (a duty-cycled beacon interval)
            self.flagged = {k for p in self.peers.values() for k in p.conflicts}
            self.record(
                EventKind.UPLOADED,
                flagged=sorted(levels),
                levels={str(k): v for k, v in sorted(levels.items())},
                verified=True,
                offset_m=self.settings.offset.delta,
                why=why,
            )

    # ------------------------------------------------------------------ Bob

    async def _serve(self) -> None:
        while True:
            peer, session = await self.endpoint.accept()
            self._spawn(self._answer(peer, session))

    def _near(self, path: list[tuple[int, int]], horizon: int) -> list[tuple[int, int]]:
        """The part of the remaining path a run with this horizon compares (a full run's
        horizon is 0: all of it)."""
        return near_cut(path, horizon, self._here(), least=NEAR_SEGMENTS)

    def _bob_path(self, hello: Hello) -> list[tuple[int, int]]:
        _, path = self._remaining_path()
        return point_as_segment(self._near(path, hello.horizon_m))  # hovering: a point

    async def _answer(self, peer: int, session: int) -> None:
        """Answer a run request -- only once it has shown who asks (a trusted certificate, a
        signature, a fresh time, not a replay) and that the run is plausible and within the
        budget: nobody else makes us work, and what goes back is a one-byte abort code or a
        signed refusal, never anything about our path."""
        setups = self.chooser_setups.setdefault(peer, {})
        self._answering += 1
        try:
            request = await self.endpoint.receive(peer, session)
            admitted = await self._admit(peer, session, request)
            if admitted is None:
                return
            responder, hello, ticket = admitted
            async with self._radio.turn(ANSWER_NEAR if hello.horizon_m > 0 else ANSWER_FULL):
                self._sessions += 1
                bob = Bob(self._bob_path, keys=self.bob_keys, setups=setups, geographic=True)
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
                        )
                finally:
                    self._sessions -= 1
                    if bob.state is not State.DONE:  # no last message: Alice learnt nothing
                        self.ledger.refund(ticket)
        except AuthenticationError as exc:
            self.record(EventKind.ANSWER_FAILED, peer=peer, auth=str(exc))
            return
        except (ProtocolError, LinkError, ValueError) as exc:
            self.record(EventKind.ANSWER_FAILED, peer=peer, error=str(exc))
            return
        except Exception as exc:  # nothing may stop the companion
            log.exception("node %d: answering %d failed", self.settings.node, peer)
            self.record(EventKind.ANSWER_FAILED, peer=peer, error=f"internal: {exc!r}")
            return
        finally:
            self._answering -= 1
            self._wake.set()
            while len(setups) > SETUPS_PER_PEER:  # the oldest go first
                setups.pop(next(iter(setups)))
        if report.refused is not None:
            self.record(EventKind.REFUSED, peer=peer, reason=report.refused.name)
            return
        self.record(
            EventKind.ANSWERED,
            peer=peer,
            bytes=report.bytes_sent,
            auth_bytes=report.auth_bytes_sent,
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
            self.record(EventKind.ANSWER_FAILED, peer=peer, auth=str(exc))
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
            self._cert_wanted = True
            self._cert_now.set()
            if self.clock.now() - self._unknown_refused >= self._asked_every_s:
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
            self.endpoint.abort(peer, session, AbortCode.AUTH)
            self.record(EventKind.ANSWER_FAILED, peer=peer, auth=str(exc))
            return None
        try:
            hello = Hello.from_bytes(init.hello)
        except ProtocolError as exc:
            self.endpoint.abort(peer, session, AbortCode.PROTOCOL)
            self.record(EventKind.ANSWER_FAILED, peer=peer, error=str(exc))
            return None
        if known.role is Role.ALICE:
            if self.settings.node < peer:
                # Both took the pair as Alice (their views of who was on the ground crossed):
                # exactly one of a pair adjusts -- the lower node id keeps the role.
                await self._refuse(peer, session, responder, Refusal.ROLE)
                return None
            self.record(EventKind.YIELDED, peer=peer, reason="the peer has the lower node id")
        operator = neighbour.operator
        allowed = min(operator.max_segments, 1 << min(known.beacon.size_class, MAX_SIZE_CLASS))
        if hello.m > allowed:  # more than its beacon announced or its operator allows
            await self._refuse(peer, session, responder, Refusal.SIZE)
            return None
        try:
            ticket = self.ledger.admit(
                known.identity, operator.key.fingerprint, operator.max_runs_per_hour, wall, BOB
            )
        except BudgetExceeded as exc:
            self.record(EventKind.BUDGET, peer=peer, error=str(exc))
            await self._refuse(peer, session, responder, Refusal.BUDGET)
            return None
        known.role = Role.BOB
        known.conflicts.clear()  # as Bob we do not adjust for this peer
        return responder, hello, ticket

    async def _refuse(self, peer: int, session: int, responder: Responder, code: Refusal) -> None:
        self.record(EventKind.REFUSED, peer=peer, reason=code.name)
        try:
            await self.endpoint.send(peer, session, responder.refuse(code))
        except LinkError:
            pass
        finally:
            self.endpoint.close_session(peer, session)
