"""A world to attack: real companions (runtime, link, authentication, state on disk) on one
simulated radio in virtual time, with a fake autopilot (the attacks are on the radio, not on
MAVLink), and an attacker who hears every frame and can put any frame on the air."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from companion.app.runtime import Companion, CompanionSettings, Credentials
from companion.auth.beacon_keys import BeaconKeys
from companion.auth.session import Initiator, Route
from companion.auth.trust import UnknownPeers
from companion.mission.files import read_plan
from companion.mission.items import MissionItem
from companion.mission.levels import Slots
from companion.neighbours.beacon import Beacon, CertBeacon
from companion.neighbours.beacon import keys_hash as beacon_keys_hash
from companion.radio import PROFILES, Clock, LinkEndpoint
from companion.radio.frames import (
    OVERHEAD,
    AbortCode,
    Flag,
    Frame,
    FrameError,
    FrameType,
    decode_frame,
)
from companion.runs.exchange import RunReport, run_alice
from companion.sim.fleet import make_fleet
from companion.sim.medium import Channel, Impairments, SimMedium
from protocol.geo.geometry import Point
from protocol.geo.grid import GridSpec
from protocol.intersection import Alice, Bob
from protocol.messages import Suite

SCENARIOS = Path(__file__).resolve().parents[3] / "sitl_configs" / "scenarios"
PROFILE = PROFILES["us915-sf7"]


class FakeAutopilot:
    """What the runtime asks of an autopilot, recorded."""

    def __init__(self, mission: list[MissionItem]) -> None:
        self.mission = mission
        self.uploads: list[list[MissionItem]] = []
        self.pauses = self.resumes = 0

    async def download(self) -> list[MissionItem]:
        return self.mission

    async def replace_mission(self, new: list[MissionItem], held: list[MissionItem]) -> None:
        self.uploads.append(new)
        self.mission = new

    async def pause(self) -> None:
        self.pauses += 1

    async def resume(self) -> None:
        self.resumes += 1


@dataclass
class Sniffer:
    """Every frame on the air, decoded, with who sent it and when."""

    frames: list[tuple[float, Frame]] = field(default_factory=list)

    def of(self, kind: FrameType, src: int | None = None) -> list[Frame]:
        return [f for _, f in self.frames if f.type is kind and (src is None or f.src == src)]


class Tap:
    """A transport in the middle of a node's radio: sees what the node receives and may
    change or drop it (an attacker who jams a frame and sends its own in its place)."""

    def __init__(self, inner: Any, sniffer: Sniffer, clock: Clock) -> None:
        self.inner, self.sniffer, self.clock = inner, sniffer, clock
        self.rewrite: Callable[[Frame], Frame | None] | None = None
        self._deliver: Callable[[bytes], None] | None = None

    def set_receiver(self, callback: Callable[[bytes], None]) -> None:
        self._deliver = callback
        self.inner.set_receiver(self._on_bytes)

    def _on_bytes(self, data: bytes) -> None:
        assert self._deliver is not None
        try:
            frame = decode_frame(data)
        except FrameError:
            self._deliver(data)
            return
        if self.rewrite is not None:
            changed = self.rewrite(frame)
            if changed is None:
                return
            data = changed.encode()
        self._deliver(data)

    def channel_busy(self) -> bool:
        return bool(self.inner.channel_busy())

    async def transmit(self, frame: bytes, airtime: float) -> None:
        """The sniffer has a frame once its transmission ended: one cut off by its sender's
        stop is heard by nobody, the attacker included (recorded at its start time)."""
        start = self.clock.now()
        await self.inner.transmit(frame, airtime)
        with contextlib.suppress(ValueError):
            self.sniffer.frames.append((start, decode_frame(frame)))

    async def close(self) -> None:
        await self.inner.close()


@dataclass
class World:
    clock: Clock
    medium: SimMedium
    sniffer: Sniffer
    drones: dict[int, Companion]
    autopilots: dict[int, FakeAutopilot]
    taps: dict[int, Tap]
    credentials: dict[int, Credentials]
    _injector: Any = None

    def events(self, node: int, kind: str) -> list[dict[str, Any]]:
        return [e.detail for e in self.drones[node].events if e.kind == kind]

    async def attacker(self, node: int) -> LinkEndpoint:
        """A radio of the attacker's on the same channel (any node id it likes)."""
        tap = Tap(self.medium.attach(node), self.sniffer, self.clock)
        endpoint = LinkEndpoint(node, tap, PROFILE, clock=self.clock)
        await endpoint.start()
        return endpoint

    async def rogue(self, node: int) -> Rogue:
        """A certified identity made with the world (``extra``), on a radio of its own."""
        return Rogue(node, await self.attacker(node), self.credentials[node])

    async def inject(self, data: bytes, airtime: float = 0.05) -> None:
        """Put raw bytes on the air from a radio of the attacker's (any source address it
        writes into the frame: the medium's node 0xFFFE only carries them)."""
        if self._injector is None:
            self._injector = self.medium.attach(0xFFFE)
        for _ in range(200):  # it listens before it talks, as a radio would (20 s at most)
            if not self._injector.channel_busy():
                break
            await self.clock.sleep(0.1)
        await self._injector.transmit(data, PROFILE.airtime(len(data)))
        await self.clock.sleep(PROFILE.turnaround_s)

    async def inject_message(self, src: int, dst: int, session: int, data: bytes) -> None:
        """A whole message as if ``src`` sent it (fragments, the last asking for an ACK)."""
        size = PROFILE.max_frame - OVERHEAD
        count = max(1, -(-len(data) // size))
        for i in range(count):
            flags = Flag.ACK_REQ if i == count - 1 else Flag.NONE
            chunk = data[i * size : (i + 1) * size]
            await self.inject(
                Frame(FrameType.DATA, src, dst, session, 0, i, count, chunk, flags).encode()
            )

    async def stop(self) -> None:
        for drone in self.drones.values():
            await drone.stop()


DRONES = {1: "delivery_east.plan", 2: "inspection_north.plan"}


async def world(
    state: Path,
    *,
    operators: dict[int, str] | None = None,
    untrusted: tuple[str, ...] = (),
    unknown: UnknownPeers = UnknownPeers.IGNORE,
    missions: dict[int, str] | None = None,
    settings: dict[str, Any] | None = None,
    loss: float = 0.0,
    extra: dict[int, str] | None = None,
    profile: str = "us915-sf7",
    paper_keys: bool = False,
) -> World:
    """Drones on the ground at their homes, their companions started (no MAVSDK: a fake
    autopilot), beaconing, listening and comparing on one simulated US915 SF7 channel.
    ``extra``: identities (node -> operator) certified alongside, for an attacker to use."""
    missions = missions or DRONES
    operators = operators or {}
    clock = Clock()
    medium = SimMedium(Channel(Impairments(loss=loss), seed=3), clock)
    sniffer = Sniffer()
    creds = make_fleet(
        [(node, operators.get(node, "fleet")) for node in missions] + list((extra or {}).items()),
        state,
        untrusted=untrusted,
        unknown=unknown,
        paper_keys=paper_keys,
    )
    drones, autopilots, taps = {}, {}, {}
    for node, plan in missions.items():
        items, home = read_plan(SCENARIOS / plan)
        assert home is not None
        tap = Tap(medium.attach(node), sniffer, clock)
        endpoint = LinkEndpoint(node, tap, PROFILES[profile], clock=clock)
        autopilot = FakeAutopilot(items)
        c = Companion(
            CompanionSettings(
                node=node,
                autopilot_url="",
                # no run limit: the paper suite's CPU, charged to the virtual clock, takes
                # longer than the product's (the replays run without one too)
                **({"run_timeout_s": None} | (settings or {})),
            ),
            endpoint,
            autopilot,  # type: ignore[arg-type]
            creds[node],
        )
        home_e7 = (round(home[0] * 1e7), round(home[1] * 1e7))
        c.flight.load(list(items), (*home_e7, home[2]))
        c.vehicle.position = (*home_e7, home[2])
        c.epoch = clock.now()
        drones[node], autopilots[node], taps[node] = c, autopilot, tap
    w = World(clock, medium, sniffer, drones, autopilots, taps, creds)
    for c in drones.values():
        await c.endpoint.start()
        await c.start_radio()
    return w


@dataclass
class Rogue:
    """A certified drone that deviates: it speaks the radio protocol by hand."""

    node: int
    endpoint: LinkEndpoint
    credentials: Credentials
    keys: BeaconKeys = field(default_factory=BeaconKeys)
    counter: int = 0

    async def announce(self, w: World, position: tuple[int, int], size_class: int = 1) -> None:
        """Its certificate, then a signed position beacon: the drones nearby now know it."""
        identity = self.credentials.identity
        await self.endpoint.beacon(CertBeacon(identity.cert).encode())
        self.counter += 1
        beacon = Beacon(
            position[0], position[1], 500, False, frozenset({Suite.COMPACT}), 1,
            int(w.clock.wall()), self.counter, Slots(), size_class,
        )  # fmt: skip
        keys = beacon_keys_hash(b"r" * 16, self.keys.public, b"")
        await self.endpoint.beacon(beacon.signed(self.node, identity.key, self.keys.public, keys))
        await w.clock.sleep(5)

    async def compare(
        self,
        w: World,
        victim: int,
        path: tuple[Point, ...],
        grid: GridSpec,
        machine: type[Alice] = Alice,
        horizon_m: int = 0,
        ask_n: int = 0,
    ) -> tuple[RunReport, list[int]]:
        """A whole run as Alice (the real machine, or a ``machine`` of the attacker's, and
        the real session) against ``victim`` (a near run with ``horizon_m``, asking ``ask_n``
        segments); its report and the sizes of the victim's messages as they went on the air."""
        victim_cert = w.credentials[victim].identity.cert
        alice = machine(path, grid, horizon_m=horizon_m, ask_n=ask_n)
        start = len(w.sniffer.frames)

        def secure(session: int) -> Initiator:
            route = Route(self.node, victim, session)
            return Initiator(self.credentials.identity, victim_cert, route, w.clock.wall())

        report = await run_alice(self.endpoint, victim, alice, secure=secure, timeout=600)
        sizes: dict[int, int] = {}
        for _, frame in w.sniffer.frames[start:]:
            if frame.type is FrameType.DATA and frame.src == victim and frame.dst == self.node:
                sizes[frame.seq] = sizes.get(frame.seq, 0) + len(frame.payload)
        return report, [sizes[k] for k in sorted(sizes)]


def aborts_are_codes(w: World) -> None:
    """Nothing but a one-byte code in any abort on the air (no text, no position), and its
    proof: a 16-byte MAC (keyed session) or a signature (before the keys)."""
    for frame in w.sniffer.of(FrameType.ABORT):
        assert len(frame.payload) in (1, 17, 65) and frame.payload[0] in set(AbortCode)


def count_bobs(monkeypatch: Any) -> list[Any]:
    """Every Bob machine a companion builds from now on (a request refused before any work
    builds none)."""
    import companion.runs.bob

    built: list[Any] = []
    real_bob = Bob

    def counting_bob(*args: Any, **kwargs: Any) -> Any:
        built.append(args)
        return real_bob(*args, **kwargs)

    monkeypatch.setattr(companion.runs.bob, "Bob", counting_bob)
    return built
