"""Scripted replays: mock autopilots (or PX4 SITL), real MAVSDK, companions, one radio --
or, in virtual time, mock vehicles in this process (:mod:`companion.sim.inproc`).

``drone-deconflict replay SCENARIO.toml``.  Each drone of the scenario
(:mod:`companion.sim.scenario`) gets a :class:`~companion.sim.mock_autopilot.MockAutopilot` on
loopback UDP (or a PX4 SITL vehicle, :mod:`companion.sim.px4`), a
:class:`~companion.mission.autopilot.Autopilot` (MAVSDK) and a
:class:`~companion.app.runtime.Companion` on the shared simulated channel.  The missions are flown
in scaled time (mocks: on a paced clock,
:mod:`companion.sim.paced_clock`) until every drone has finished or the time limit passes.  A
baseline without companions (same missions, same schedule, the same flight model stepped
offline) gives the separations one would have had; :mod:`companion.sim.metrics` measures both
into the typed report (:mod:`companion.sim.report`), :mod:`companion.sim.plot` and
:mod:`companion.sim.export` make figures and files of it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import socket
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from companion.app.runtime import Companion, CompanionSettings
from companion.events import Event, EventKind, Retimed, RunResult, RunStarted, Uploaded
from companion.mission.autopilot import Autopilot, AutopilotBase
from companion.mission.items import MissionItem
from companion.mission.personalities import personality
from companion.mission.planner import OffsetSettings
from companion.mission.schedule import SeparationSettings
from companion.radio import Clock, LinkEndpoint, LinkProfile, profile
from companion.radio.config import LinkConfig
from companion.runs.failsafe import FailsafeSettings
from companion.settings import Credentials
from companion.sim.fleet import make_fleet
from companion.sim.inproc import InProcessVehicle
from companion.sim.medium import Channel, Impairments, SimMedium
from companion.sim.metrics import SCREEN_FROM, build_report
from companion.sim.mock_autopilot import Faults, FlightModel, MockAutopilot
from companion.sim.paced_clock import PacedClock
from companion.sim.px4 import Px4Build
from companion.sim.report import ReplayReport
from companion.sim.scenario import DroneSpec, Scenario, ScenarioError
from companion.sim.vehicles import MockVehicle, Px4SitlVehicle, ReplayVehicle, Track
from companion.sim.virtual_time import VirtualTimeLoop, run_simulated
from companion.tasks import spawn
from protocol.geo.geodesy import metres_per_degree

log = logging.getLogger(__name__)
# SIH lock-step speed factor for two PX4 vehicles, their companions and the protocol on 2
# cores: at 10 the crossing resolves but the in-flight crossing's first result came at 105 s
# (33 s at 4x, 40 s at 6x: the companions' CPU time counts 10x over in simulated time with
# two px4 processes taking 1.2 cores) and the drones met at 4 m
PX4_SPEED_MAX = 5.0
VIRTUAL_RATE_HZ = 5.0  # a virtual replay's vehicles step (and report) this often
VIRTUAL_LOOK_S = 0.2  # and the schedule (take-offs, holds, the end) is looked at this often
PARKED_LOOK_S = 1.0  # ... or this often while none flies (hours on the ground: lossy_sf9)


@dataclass(frozen=True)
class Tracks:
    """What a plot needs beyond the report: flown and baseline trajectories, ground paths."""

    flown: dict[int, Track]
    baseline: dict[int, Track]
    paths: dict[int, list[tuple[int, int]]]


@dataclass(frozen=True)
class Replay:
    report: ReplayReport  # its to_json() is what --json prints
    tracks: Tracks


TOLD = frozenset(
    {
        EventKind.RUN_STARTED,
        EventKind.RESULT,
        EventKind.RUN_FAILED,
        EventKind.UPLOADED,
        EventKind.PRECAUTIONARY,
        EventKind.TASK_FAILED,
        EventKind.PLAN_FAILED,
        EventKind.UPLOAD_FAILED,
        EventKind.RETIMED,
    }
)


def _story(event: Event) -> str:
    """One companion event as a progress line of the replay."""
    p = event.payload
    if isinstance(p, RunStarted):
        return (
            f"{p.phase} run with {p.peer} started ({p.segments} segments, about "
            f"{p.estimate_s:.0f} s)"
        )
    if isinstance(p, RunResult):
        flagged = ", ".join(map(str, p.flagged)) or "none"
        return (
            f"result of the {p.phase} run with {p.peer}: segments {flagged} conflict "
            f"({p.bytes} B sent, {p.run_s:.0f} s)"
        )
    if isinstance(p, Uploaded):
        return "edit uploaded and verified"
    if isinstance(p, Retimed):
        if p.held:
            return "holding: its windows are open from now on, every peer compares again"
        if p.on_ground:
            return "still on the ground after half its wait: every peer compares again"
        way = "behind" if p.drift_s > 0 else "ahead of"
        return f"{abs(p.drift_s):.0f} s {way} its windows: every peer compares again"
    details = ", ".join(f"{k}={v}" for k, v in event.detail.items())
    return f"{event.kind.replace('_', ' ')} ({details})"


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _fly_offline(scenario: Scenario) -> dict[int, list[tuple[float, float, float, float]]]:
    """The baseline: the same missions and schedule -- take-offs and scripted holds -- through
    the same flight model, no radio."""
    rate = 10.0
    mocks = {
        d.id: MockAutopilot(
            0,
            mission=d.mission,
            home=d.home,
            ardupilot=d.ardupilot,
            flight=FlightModel(cruise_m_s=scenario.cruise_m_s, rate_hz=rate),
        )
        for d in scenario.drones
    }
    started: set[int] = set()
    t, dt = 0.0, 1.0 / rate
    # a busy sky's vehicles on the ground (before take-off, after landing) a step a second,
    # as the virtual replay's own vehicles are
    sparse = len(scenario.drones) > SCREEN_FROM
    while t < scenario.time_limit_s:
        waiting = [d.takeoff_delay_s for d in scenario.drones if d.id not in started]
        if waiting and not any(m.flying for m in mocks.values()) and min(waiting) > t + dt:
            idle = min(waiting) - t  # nobody in the air before the next take-off: one step
            for mock in mocks.values():
                mock.advance(idle)
            t += idle
            continue
        for d in scenario.drones:
            mock = mocks[d.id]
            if d.id not in started and t >= d.takeoff_delay_s:
                if sparse and t - mock.craft.t > 1e-9:
                    mock.advance(t - mock.craft.t)  # (parked until now)
                mock.take_off()
                started.add(d.id)
            if d.pause is not None and d.id in started:
                at, length = d.pause
                if at <= t < at + dt:
                    mock.pause()
                elif at + length <= t < at + length + dt:
                    mock.resume()
            behind = t + dt - mock.craft.t
            if not sparse:
                mock.advance(dt)
            elif mock.mission_running or mock.holding or mock.flying or behind >= 1.0 - 1e-9:
                mock.advance(behind)
        t += dt
        if len(started) == len(mocks) and not any(
            m.mission_running or m.holding for m in mocks.values()
        ):
            break
    return {k: m.trajectory for k, m in mocks.items()}


def run_virtual(
    scenario: Scenario,
    *,
    progress: bool = False,
    channel_log: list[tuple[float, float, int]] | None = None,
) -> Replay:
    """Fly ``scenario`` in virtual time (:func:`run_replay` with ``virtual``, on its own
    :class:`~companion.radio.clock.VirtualTimeLoop`)."""
    return run_simulated(
        run_replay(scenario, progress=progress, virtual=True, channel_log=channel_log)
    )


def _vehicle(
    d: DroneSpec,
    scenario: Scenario,
    px4: Px4Build | None,
    ts: float,
    flight: FlightModel,
    clock: Clock,
    *,
    virtual: bool,
) -> ReplayVehicle:
    """Drone ``d``'s vehicle: in this process (virtual), a mock autopilot on loopback UDP, or
    a PX4 SITL instance of the build ``px4``."""
    if virtual:
        return InProcessVehicle(
            d.mission, d.home, ardupilot=d.ardupilot, flight=flight, clock=clock
        )
    if px4 is None:
        return MockVehicle(
            d.mission,
            d.home,
            ardupilot=d.ardupilot,
            flight=flight,
            faults=d.faults,
            bind_port=free_udp_port(),
            send_port=free_udp_port(),
            clock=clock,
        )
    if d.ardupilot:
        raise ScenarioError(f"drone {d.id}: PX4 SITL cannot fly an ArduPilot drone")
    return Px4SitlVehicle(
        px4, d.mission, d.home, speed_factor=ts, cruise_m_s=scenario.cruise_m_s, clock=clock
    )


def _settings(d: DroneSpec, scenario: Scenario, url: str) -> CompanionSettings:
    """Drone ``d``'s companion settings: the scenario's, else the companion's defaults."""
    return CompanionSettings(
        node=d.id,
        autopilot_url=url,
        ardupilot=d.ardupilot,
        offset=OffsetSettings(offset_m=scenario.offset_m),
        beacon_interval_s=scenario.beacon_interval_s,
        grid_radius_m=scenario.grid_radius_m,
        grid_resolution_mm=scenario.grid_resolution_mm,
        lookahead_s=scenario.lookahead_s,
        run_timeout_s=None,  # a scenario's runs end by its own time limit
        cruise_m_s=scenario.cruise_m_s,
        failsafe=FailsafeSettings(action=scenario.failsafe),
        separation=SeparationSettings(scenario.separation_m, scenario.vertical_separation_m),
    )


class _Script:
    """What the scenario does to its drones as simulated time passes: take-offs (a drone
    about to take off waits for its comparisons when the scenario says so), pauses, a
    companion that vanishes; and the companions' events told as progress lines."""

    def __init__(
        self,
        scenario: Scenario,
        vehicles: dict[int, ReplayVehicle],
        companions: dict[int, Companion],
        vanished: dict[int, Companion],
        say: Callable[[str], None],
    ) -> None:
        self.scenario, self.vehicles, self.say = scenario, vehicles, say
        self.companions, self.vanished = companions, vanished
        self.started: set[int] = set()
        self.powered = {d.id for d in scenario.drones if d.companion_start_s <= 0}
        self.paused: dict[int, bool] = {}  # held by the scenario (False), and flying on (True)
        self.told = {d.id: 0 for d in scenario.drones}  # companion events already told

    async def fly(self, clock: Clock, origin: float, *, virtual: bool) -> bool:
        """Until every mission is flown (True) or the scenario's time limit."""
        while True:
            sim = clock.now() - origin
            await self.step(sim)
            flying = any(v.flying for v in self.vehicles.values())
            done = len(self.started) == len(self.vehicles) and not flying
            if done or sim >= self.scenario.time_limit_s:
                self.say(f"t={sim:.0f} s: {'all missions flown' if done else 'time limit'}")
                return done
            if virtual:
                await clock.sleep(self._look_s(sim))
            else:
                await asyncio.sleep(0.01)

    def _look_s(self, sim: float) -> float:
        """Until the next look at the schedule (virtual time): soon while any vehicle
        flies, else at the next thing due (a take-off, a companion powering up or off)
        within a second (a scripted pause comes in flight)."""
        if any(v.flying for v in self.vehicles.values()):
            return VIRTUAL_LOOK_S
        due = [
            t
            for d in self.scenario.drones
            for t in (d.takeoff_delay_s, d.companion_start_s, d.companion_stop_s)
            if t is not None and t > sim
        ]
        return max(min([PARKED_LOOK_S, *(t - sim for t in due)]), 0.0)

    async def step(self, sim: float) -> None:
        for ident, companion in self.companions.items():
            for event in companion.events[self.told[ident] :]:
                if event.kind in TOLD:
                    self.say(f"t={event.t:.0f} s: drone {ident}: {_story(event)}")
            self.told[ident] = len(companion.events)
        for d in self.scenario.drones:
            await self._power(d, sim)
            await self._vanish(d, sim)
            await self._pause(d, sim)
            waiting = (
                d.hold_for_comparisons
                and d.id in self.companions
                and self.companions[d.id].alice.comparing
            )
            if d.id not in self.started and sim >= d.takeoff_delay_s and not waiting:
                await self.vehicles[d.id].take_off()
                self.started.add(d.id)
                self.say(f"t={sim:.0f} s: drone {d.id} takes off")

    async def _power(self, d: DroneSpec, sim: float) -> None:
        """A companion that powers up late (before its take-off), and off once landed."""
        companion = self.companions.get(d.id)
        if companion is None:
            return
        if d.id not in self.powered and sim >= d.companion_start_s:
            await companion.start()
            self.powered.add(d.id)
            self.say(f"t={sim:.0f} s: drone {d.id}'s companion powers up")
        elif d.companion_off_landed and d.id in self.started and not self.vehicles[d.id].flying:
            await companion.stop()
            self.vanished[d.id] = self.companions.pop(d.id)
            self.say(f"t={sim:.0f} s: drone {d.id} has landed, its companion is off")

    async def _vanish(self, d: DroneSpec, sim: float) -> None:
        gone = self.companions.get(d.id)
        due = d.companion_stop_s is not None and sim >= d.companion_stop_s
        if due and gone and (gone.air.in_run or not d.companion_stop_in_run):
            await gone.stop()  # the peer vanishes: its radio goes silent
            self.vanished[d.id] = self.companions.pop(d.id)
            self.say(f"t={sim:.0f} s: drone {d.id}'s companion vanishes")

    async def _pause(self, d: DroneSpec, sim: float) -> None:
        if d.pause is None:
            return
        if d.id in self.started and d.id not in self.paused and sim >= d.pause[0]:
            await self.vehicles[d.id].pause()
            self.paused[d.id] = False
            self.say(f"t={sim:.0f} s: drone {d.id} is held for {d.pause[1]:.0f} s")
        elif self.paused.get(d.id) is False and sim >= d.pause[0] + d.pause[1]:
            await self.vehicles[d.id].resume()
            self.paused[d.id] = True
            self.say(f"t={sim:.0f} s: drone {d.id} flies on")


def _check(scenario: Scenario, px4: Px4Build | None, *, virtual: bool) -> None:
    """What a virtual replay cannot fly: PX4 SITL (lock-step real time), MAVLink faults."""
    if virtual and px4 is not None:
        raise ScenarioError("PX4 SITL runs in real time: no virtual replay with it")
    if virtual and not isinstance(asyncio.get_running_loop(), VirtualTimeLoop):
        raise RuntimeError("a virtual replay runs on a VirtualTimeLoop (run_virtual)")
    faulty = [d.id for d in scenario.drones if d.faults != Faults()]
    if virtual and faulty:
        raise ScenarioError(f"drones {faulty}: MAVLink faults need the replay over MAVSDK")


async def _autopilot(vehicle: ReplayVehicle, d: DroneSpec) -> AutopilotBase:
    """The companion's autopilot: the in-process one, or MAVSDK on the vehicle's API link."""
    if isinstance(vehicle, InProcessVehicle):
        return vehicle.autopilot
    return await Autopilot.connect(vehicle.api_url, personality=personality(d.ardupilot))


async def _shut_down(
    companions: dict[int, Companion],
    autopilots: list[AutopilotBase],
    vehicles: dict[int, ReplayVehicle],
    say: Callable[[str], None],
) -> dict[int, list[MissionItem]]:
    """Stop the companions, MAVSDK and the vehicles; the mission each vehicle held at the end
    (read after MAVSDK is off the vehicle; empty when it cannot be read)."""
    for companion in companions.values():
        await companion.stop()
    for ap in autopilots:
        await ap.close()
    held: dict[int, list[MissionItem]] = {}
    for k, vehicle in vehicles.items():
        try:
            held[k] = await vehicle.held_mission()
        except Exception as exc:  # the report says "other", the log says why
            log.warning("drone %d: the mission held at the end is unknown: %s", k, exc)
            held[k] = []
    for vehicle in vehicles.values():
        await vehicle.stop()
    return held


def _clock(
    scenario: Scenario, px4: Px4Build | None, px4_speed_max: float, *, virtual: bool
) -> tuple[float, PacedClock | None, Clock]:
    """The replay's time scale and clock (and the paced clock, when the mocks fly on one)."""
    ts = scenario.time_scale if px4 is None else min(scenario.time_scale, px4_speed_max)
    # Mocks fly on a clock paced by this process (a busy machine does not pass as flight
    # time); PX4 SITL keeps lock-step real time, so with it the plain scaled clock; a virtual
    # replay's clock is its loop's, and every step's CPU passes as link time.
    paced = PacedClock(ts) if px4 is None and not virtual else None
    clock = paced or (Clock(charges_cpu=True) if virtual else Clock(ts))
    return ts, paced, clock


def _radio(
    scenario: Scenario, clock: Clock, vehicles: dict[int, ReplayVehicle]
) -> tuple[SimMedium, LinkProfile]:
    """The shared simulated channel and the link profile of the scenario (radios in range
    of each other where the vehicles are, when it has a radio range)."""
    channel = Channel(Impairments(loss=scenario.loss), scenario.seed)
    if scenario.radio_range_m is not None:
        home = scenario.drones[0].home
        channel.reach = _in_range(scenario.radio_range_m, (home[0], home[1]), clock, vehicles)
    return SimMedium(channel, clock), profile(scenario.link_profile)


def _in_range(
    range_m: float,
    ref: tuple[float, float],
    clock: Clock,
    vehicles: dict[int, ReplayVehicle],
) -> Callable[[int, int], bool]:
    """reach(a, b): the vehicles of nodes a and b (their last track points) are at most
    ``range_m`` apart on the ground (a flat projection about ``ref``: a radio range is not
    known to the metre); positions are looked up once per instant."""
    north, east = metres_per_degree(ref[0])
    limit = range_m * range_m
    seen: dict[int, tuple[float, float]] = {}
    instant = [math.nan]

    def where(node: int) -> tuple[float, float]:
        now = clock.now()
        if now != instant[0]:
            seen.clear()
            instant[0] = now
        point = seen.get(node)
        if point is None:
            track = vehicles[node].trajectory
            lat, lon = (track[-1][1], track[-1][2]) if track else ref
            point = seen[node] = (lat * north, lon * east)
        return point

    def reach(a: int, b: int) -> bool:
        (ya, xa), (yb, xb) = where(a), where(b)
        return (ya - yb) ** 2 + (xa - xb) ** 2 <= limit

    return reach


def _fleet(scenario: Scenario, root: Path) -> dict[int, Credentials]:
    """The drones' credentials (state under ``root``), trusted as the scenario says."""
    return make_fleet(
        [(d.id, d.operator) for d in scenario.drones],
        root,
        untrusted=scenario.untrusted_operators,
        unknown=scenario.unknown_peers,
    )


def _sayer(progress: bool) -> Callable[[str], None]:
    """Progress lines on stderr, or nothing."""

    def say(message: str) -> None:
        if progress:
            print(f"  ... {message}", file=sys.stderr, flush=True)

    return say


async def _bring_up(
    scenario: Scenario,
    px4: Px4Build | None,
    ts: float,
    clock: Clock,
    radio: tuple[SimMedium, LinkProfile],
    origin: float,
    fleet: dict[int, Credentials],
    say: Callable[[str], None],
    *,
    virtual: bool,
    mocks: dict[int, ReplayVehicle],
    companions: dict[int, Companion],
    autopilots: list[AutopilotBase],
) -> None:
    """Start every drone's vehicle, autopilot link and companion on the shared channel (into
    ``mocks``, ``autopilots`` and ``companions`` as they come up: what is up is shut down)."""
    medium, link = radio
    specs = {d.id: d for d in scenario.drones}
    flight = FlightModel(
        cruise_m_s=scenario.cruise_m_s,
        time_scale=1.0 if virtual else ts,
        rate_hz=VIRTUAL_RATE_HZ if virtual else 20.0,
    )
    for d in scenario.drones:
        vehicle = _vehicle(d, scenario, px4, ts, flight, clock, virtual=virtual)
        mocks[d.id] = vehicle
        await vehicle.start(origin)
        ap = await _autopilot(vehicle, d)
        autopilots.append(ap)
        settings = _settings(d, scenario, vehicle.api_url)
        endpoint = LinkEndpoint(
            d.id, medium.attach(d.id), link, LinkConfig(channels=scenario.channels), clock=clock
        )
        companions[d.id] = Companion(settings, endpoint, ap, fleet[d.id])
        via = "MAVSDK" if isinstance(ap, Autopilot) else "no MAVLink"
        say(f"drone {d.id}: {vehicle.kind} vehicle up ({via})")
    # The companions start together: one set up earlier would have the radio (and its
    # first runs) to itself while the others' vehicles still start.  (A drone whose
    # companion powers up later is started by the script.)
    now = [c for k, c in companions.items() if specs[k].companion_start_s <= 0]
    await asyncio.gather(*(companion.start() for companion in now))
    say("companions up")


def _restart_clocks(
    clock: Clock, mocks: dict[int, ReplayVehicle], companions: dict[int, Companion]
) -> float:
    """Simulated time zero, now that everything is up: the vehicles' and companions' too."""
    origin = clock.now()
    for mock in mocks.values():
        mock.restart_clock(origin)
    for companion in companions.values():
        companion.epoch = clock.now()
    return origin


async def _stop_ticker(
    paced: PacedClock | None, ticker: asyncio.Task[None] | None, say: Callable[[str], None]
) -> None:
    """Stop pacing the clock, and say how long it was held back."""
    if paced is not None and ticker is not None:
        ticker.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await ticker
        say(f"clock held back for {paced.lost_s:.1f} real s (stalls, inline computation)")


async def run_replay(
    scenario: Scenario,
    *,
    progress: bool = False,
    px4: Px4Build | None = None,
    px4_speed_max: float = PX4_SPEED_MAX,
    virtual: bool = False,
    channel_log: list[tuple[float, float, int]] | None = None,
) -> Replay:
    """Fly ``scenario``: mock autopilots over MAVLink and MAVSDK, PX4 SITL vehicles from the
    build ``px4`` (their speed factor, and so the replay's time scale, at most
    ``px4_speed_max``), or -- ``virtual`` -- mock vehicles in this process
    (:mod:`companion.sim.inproc`) on a virtual clock (run it on a
    :class:`~companion.radio.clock.VirtualTimeLoop`: :func:`run_virtual`).  ``channel_log``
    receives every transmission on the channel, (start, end, node) in simulated seconds."""
    _check(scenario, px4, virtual=virtual)
    ts, paced, clock = _clock(scenario, px4, px4_speed_max, virtual=virtual)
    mocks: dict[int, ReplayVehicle] = {}
    radio = _radio(scenario, clock, mocks)
    radio[0].channel.keep_log = channel_log is not None
    companions: dict[int, Companion] = {}
    vanished: dict[int, Companion] = {}
    autopilots: list[AutopilotBase] = []
    origin = clock.now()  # simulated time zero for every vehicle and the schedule
    state = tempfile.TemporaryDirectory(prefix="replay-state-")
    fleet = _fleet(scenario, Path(state.name))
    say = _sayer(progress)
    ticker = spawn(paced.tick(), name="paced-clock", log=log) if paced is not None else None
    try:
        await _bring_up(
            scenario,
            px4,
            ts,
            clock,
            radio,
            origin,
            fleet,
            say,
            virtual=virtual,
            mocks=mocks,
            companions=companions,
            autopilots=autopilots,
        )
        origin = _restart_clocks(clock, mocks, companions)
        script = _Script(scenario, mocks, companions, vanished, say)
        done = await script.fly(clock, origin, virtual=virtual)
    finally:
        held = await _shut_down(companions, autopilots, mocks, say)
        await _stop_ticker(paced, ticker, say)
        state.cleanup()
    if channel_log is not None:
        channel_log.extend((s - origin, e - origin, n) for s, e, n in radio[0].channel.log)
    baseline = _fly_offline(scenario)
    return Replay(
        build_report(
            scenario, mocks, held, companions | vanished, baseline, done, ts, virtual=virtual
        ),
        Tracks(
            {k: m.trajectory for k, m in mocks.items()},
            baseline,
            {d.id: d.path.points for d in scenario.drones},
        ),
    )
