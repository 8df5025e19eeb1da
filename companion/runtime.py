"""The companion process: beacons, peers, private comparisons and altitude edits.

One :class:`Companion` per drone, beside its autopilot.  It beacons its coarse position and
key fingerprint; when it hears a peer within the initiation range, the role rule
(:func:`companion.beacon.alice_of`) picks exactly one of the two as Alice.  Alice compares the
part of her mission still to fly with the peer's, through the private protocol over the radio;
the peer (Bob) answers with the part of *his* mission still to fly and learns nothing.  Alice
plans the altitude edits for her flagged segments, uploads them and reads them back.  Runs per
peer are limited (probing mitigation); failures are logged, leave the mission as it was, and
never stop the process from serving other peers.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import math
import random
from dataclasses import dataclass, field
from typing import Any

from protocol.budget import BudgetExceededError, RunBudget
from protocol.errors import ProtocolError
from protocol.grid import GridSpec
from protocol.intersection import Alice, Bob, BobKeys, generate_bits_key
from protocol.wire import Suite

from .autopilot import Autopilot, AutopilotError
from .beacon import SIZE as BEACON_SIZE
from .beacon import Beacon, BeaconError, alice_of, fingerprint
from .exchange import run_alice, serve_bob
from .link.arq import LinkError, PeerAborted
from .link.endpoint import ABORT_REFUSED, LinkEndpoint
from .link.frames import OVERHEAD
from .mission import (
    MissionItem,
    ground_offset,
    path_of,
    point_as_segment,
    remaining,
    vertices,
)
from .planner import OffsetSettings, PlannerError, plan_offsets

log = logging.getLogger("companion")
_JITTER = random.SystemRandom()


@dataclass(frozen=True)
class CompanionSettings:
    node: int
    autopilot_url: str
    ardupilot: bool = False
    suite: Suite = Suite.COMPACT
    offset: OffsetSettings = field(default_factory=OffsetSettings)
    beacon_interval_s: float = 10.0
    initiation_range_m: float = 5000.0
    grid_resolution_mm: int = 500
    grid_radius_m: float = 2000.0
    max_runs_per_peer: int = 6
    run_window_s: float = 3600.0
    run_timeout_s: float | None = None
    retry_after_s: float = 60.0


@dataclass
class Peer:
    node: int
    beacon: Beacon
    heard_at: float
    compared_version: int | None = None  # the peer's mission version we compared against
    compared_own: int | None = None  # our mission version at that run
    next_try: float = 0.0
    role: str | None = None  # "alice" or "bob" once this pair has met: roles then stay


@dataclass
class Event:
    """One line of the companion's history (for logs and replay reports)."""

    t: float
    kind: str
    detail: dict[str, Any]


def _distance_m(a: tuple[int, int], b: tuple[int, int]) -> float:
    return math.hypot(*ground_offset(a[0] / 1e7, a[1] / 1e7, b[0] / 1e7, b[1] / 1e7))


def mission_version(items: list[MissionItem], ardupilot: bool) -> int:
    """16-bit digest of the ground track: altitude edits do not change it."""
    digest = hashlib.sha256(repr(path_of(items, ardupilot=ardupilot)).encode()).digest()
    return int.from_bytes(digest[:2], "big")


class Companion:
    def __init__(
        self, settings: CompanionSettings, endpoint: LinkEndpoint, autopilot: Autopilot
    ) -> None:
        self.settings = settings
        self.endpoint = endpoint
        self.autopilot = autopilot
        self.clock = endpoint.clock
        self.bob_keys = BobKeys.generate((settings.suite,))
        self.alice_keys = {settings.suite: generate_bits_key(settings.suite)}
        n = self.bob_keys.paillier.public_key.n
        self.fingerprint = fingerprint(int(n).to_bytes((int(n).bit_length() + 7) // 8, "big"))
        self.budget = RunBudget(settings.max_runs_per_peer, settings.run_window_s)
        self.peers: dict[int, Peer] = {}
        self.events: list[Event] = []
        self.original: list[MissionItem] = []
        self.mission: list[MissionItem] = []
        self.flagged: set[int] = set()
        self.position: tuple[int, int, float] = (0, 0, 0.0)  # lat, lon degE7, alt AMSL
        self.relative_alt = 0.0
        self.current_item = 0
        self._tasks: list[asyncio.Task[None]] = []
        self._children: set[asyncio.Task[None]] = set()
        self._busy = asyncio.Lock()

    # ------------------------------------------------------------------ lifecycle

    def record(self, kind: str, **detail: Any) -> None:
        self.events.append(Event(self.clock.now(), kind, detail))
        log.info("node %d %s %s", self.settings.node, kind, detail)

    async def start(self) -> None:
        self.original = await self.autopilot.download()
        self.mission = list(self.original)
        self.record(
            "mission",
            items=len(self.mission),
            segments=max(len(vertices(self.mission, ardupilot=self.settings.ardupilot)) - 1, 0),
        )
        await self.endpoint.start()
        self._tasks = [
            asyncio.create_task(self._telemetry(), name="telemetry"),
            asyncio.create_task(self._progress(), name="progress"),
            asyncio.create_task(self._beacons(), name="beacons"),
            asyncio.create_task(self._listen(), name="listen"),
            asyncio.create_task(self._serve(), name="serve"),
        ]

    def _spawn(self, work: Any) -> None:
        task = asyncio.create_task(work)
        self._children.add(task)
        task.add_done_callback(self._children.discard)

    def _budget_key(self, node: int) -> bytes:
        """Runs are counted per peer identity: node id and the key fingerprint it beacons."""
        peer = self.peers.get(node)
        return node.to_bytes(2, "big") + (peer.beacon.fingerprint if peer else b"")

    async def stop(self) -> None:
        for task in [*self._tasks, *self._children]:
            task.cancel()
        for task in [*self._tasks, *self._children]:
            with contextlib.suppress(asyncio.CancelledError):
                try:  # bounded: a stop never hangs on one task
                    await asyncio.wait_for(asyncio.shield(task), 5.0)
                except TimeoutError:
                    log.warning("node %d: task %s did not stop", self.settings.node, task)
        await self.endpoint.close()

    @property
    def comparing(self) -> bool:
        """A comparison as Alice is under way (a drone about to take off waits for it)."""
        return self._busy.locked()

    @property
    def on_ground(self) -> bool:
        return self.relative_alt < 1.0

    @property
    def version(self) -> int:
        return mission_version(self.mission, self.settings.ardupilot)

    # ------------------------------------------------------------------ vehicle state

    async def _telemetry(self) -> None:
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry = TelemetryAsync(self.autopilot.system)
        try:
            async for p in telemetry.subscribe_position():
                self.position = (
                    round(p.latitude_deg * 1e7),
                    round(p.longitude_deg * 1e7),
                    float(p.absolute_altitude_m),
                )
                self.relative_alt = float(p.relative_altitude_m)
        finally:
            telemetry.destroy()

    async def _progress(self) -> None:
        async for progress in self.autopilot.mission_raw.subscribe_mission_progress():
            self.current_item = int(progress.current)

    # ------------------------------------------------------------------ radio

    def _beacon(self) -> Beacon:
        lat, lon, alt = self.position
        return Beacon(
            lat,
            lon,
            round(alt),
            self.on_ground,
            frozenset({self.settings.suite}),
            self.version,
            self.fingerprint,
        )

    @property
    def beacon_interval(self) -> float:
        """The configured interval, stretched on duty-cycled links so beacons use at most
        5 % of the budget (EU868 SF9: one beacon per ~11 minutes)."""
        profile = self.endpoint.profile
        if profile.duty_cycle is None:
            return self.settings.beacon_interval_s
        airtime = profile.airtime(OVERHEAD + BEACON_SIZE)
        return max(self.settings.beacon_interval_s, airtime / (0.05 * profile.duty_cycle))

    async def _beacons(self) -> None:
        # Random phase and jitter: drones that beacon in lockstep collide on every beacon.
        await self.clock.sleep(_JITTER.uniform(0, self.beacon_interval))
        while True:
            if self.position[:2] != (0, 0):
                with contextlib.suppress(LinkError):
                    await self.endpoint.beacon(self._beacon().encode())
            await self.clock.sleep(self.beacon_interval * _JITTER.uniform(0.7, 1.3))

    async def _listen(self) -> None:
        while True:
            src, payload = await self.endpoint.beacons.get()
            try:
                beacon = Beacon.decode(payload)
            except BeaconError as exc:
                log.debug("bad beacon from %d: %s", src, exc)
                continue
            now = self.clock.now()
            peer = self.peers.get(src)
            if peer is None:
                peer = self.peers[src] = Peer(src, beacon, now)
                self.record("peer", peer=src, on_ground=beacon.on_ground)
            peer.beacon, peer.heard_at = beacon, now
            if self._should_compare(peer, now):
                self._spawn(self._compare(peer))

    def _should_compare(self, peer: Peer, now: float) -> bool:
        me = (self.on_ground, self.settings.node)
        them = (peer.beacon.on_ground, peer.node)
        if peer.role == "bob" or self._busy.locked():
            return False
        if peer.role is None and alice_of(me, them) != self.settings.node:
            return False
        if self.settings.suite not in peer.beacon.suites or now < peer.next_try:
            return False
        if _distance_m(self.position[:2], (peer.beacon.lat, peer.beacon.lon)) > (
            self.settings.initiation_range_m
        ):
            return False
        return (peer.compared_version, peer.compared_own) != (
            peer.beacon.mission_version,
            self.version,
        )

    # ------------------------------------------------------------------ Alice

    def _remaining_path(self) -> tuple[int, list[tuple[int, int]]]:
        ap = self.settings.ardupilot
        start = (
            remaining(self.mission, self.current_item, ardupilot=ap) if not self.on_ground else 0
        )
        return start, path_of(self.mission, ardupilot=ap)[start:]

    async def _compare(self, peer: Peer) -> None:
        async with self._busy:
            now = self.clock.now()
            peer.next_try = now + self.settings.retry_after_s
            start, path = self._remaining_path()
            if len(path) < 2:
                return
            try:
                self.budget.admit(self._budget_key(peer.node), now)
            except BudgetExceededError as exc:
                self.record("budget", peer=peer.node, error=str(exc))
                return
            lat, lon = self.position[:2]
            grid = GridSpec.geo(
                lat,
                lon,
                resolution_mm=self.settings.grid_resolution_mm,
                radius_m=self.settings.grid_radius_m,
            )
            version = peer.beacon.mission_version
            peer.role = "alice"
            try:
                alice = Alice(grid.project_path(path), grid, self.alice_keys)
                report = await run_alice(
                    self.endpoint, peer.node, alice, timeout=self.settings.run_timeout_s
                )
            except PeerAborted as exc:
                if exc.code == ABORT_REFUSED and "role" in exc.text:
                    peer.role = "bob"  # the peer already resolved this pair as Alice
                self.record("run_failed", peer=peer.node, error=str(exc))
                return
            except (ProtocolError, LinkError, ValueError) as exc:
                self.record("run_failed", peer=peer.node, error=str(exc))
                return
            flagged = {start + j for j, hit in enumerate(report.hits) if hit}
            peer.compared_version, peer.compared_own = version, self.version
            self.record(
                "result",
                peer=peer.node,
                hits=report.hits,
                first_segment=start,
                flagged=sorted(flagged),
                bytes=report.bytes_sent,
                cpu_s=report.cpu_s,
            )
            if flagged - self.flagged:
                await self._edit(self.flagged | flagged)

    async def _edit(self, flagged: set[int]) -> None:
        try:
            new = plan_offsets(
                self.original, flagged, self.settings.offset, ardupilot=self.settings.ardupilot
            )
        except PlannerError as exc:
            self.record("plan_failed", error=str(exc))
            return
        try:
            held = await self.autopilot.download()
            await self.autopilot.replace_mission(new, held)
        except AutopilotError as exc:
            self.record("upload_failed", error=str(exc))
            return
        self.mission, self.flagged = new, flagged
        self.record(
            "uploaded", flagged=sorted(flagged), verified=True, offset_m=self.settings.offset.delta
        )

    # ------------------------------------------------------------------ Bob

    async def _serve(self) -> None:
        while True:
            peer, session = await self.endpoint.accept()
            self._spawn(self._answer(peer, session))

    async def _answer(self, peer: int, session: int) -> None:
        known = self.peers.get(peer)
        if known is not None and known.role == "alice":
            # We already compared as Alice with this peer: exactly one of a pair adjusts.
            self.endpoint.abort(peer, session, ABORT_REFUSED, "role: already Alice")
            self.record("refused", peer=peer, reason="already Alice for this pair")
            return
        if known is not None:
            known.role = "bob"
        try:
            self.budget.admit(self._budget_key(peer), self.clock.now())
        except BudgetExceededError as exc:
            self.endpoint.abort(peer, session, ABORT_REFUSED, "run budget")
            self.record("budget", peer=peer, error=str(exc))
            return
        _, path = self._remaining_path()
        path = point_as_segment(path)  # a hovering drone: a point
        try:
            bob = Bob(path, self.bob_keys, geographic=True)
            await serve_bob(self.endpoint, peer, session, bob, timeout=self.settings.run_timeout_s)
        except (ProtocolError, LinkError, ValueError) as exc:
            self.record("answer_failed", peer=peer, error=str(exc))
            return
        self.record("answered", peer=peer)
