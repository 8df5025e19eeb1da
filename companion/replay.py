"""Scripted replays: mock autopilots, real MAVSDK, companions and one simulated radio.

``python -m companion replay SCENARIO.toml [--json]``.  A scenario (TOML)::

    time_scale = 20          # simulated seconds per real second
    time_limit_s = 900       # simulated
    offset_m = 10            # optional
    lookahead_s = 60         # optional: the near run covers at least this much flight
    failsafe = "climb"       # optional: "climb", "hold" or "off"
    [link]
    profile = "us915-sf7"
    loss = 0.1
    seed = 1
    [[drone]]
    id = 1
    mission = "a.plan"       # relative to the scenario file
    takeoff_delay_s = 0      # optional
    autopilot = "px4"        # or "ardupilot"
    hold_for_comparisons = true  # optional: take-off waits for a comparison under way

Each drone gets a :class:`~companion.mock_autopilot.MockAutopilot` on loopback UDP, a
:class:`~companion.autopilot.Autopilot` (MAVSDK) and a :class:`~companion.runtime.Companion`
on the shared simulated channel.  The missions are flown in scaled time until every drone has
finished or the time limit passes.  A baseline without companions (same missions, same
schedule, the same flight model stepped offline) gives the separations one would have had.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
import socket
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.geometry import path_hits
from protocol.grid import GridSpec

from .auth.trust import UnknownPeers
from .autopilot import Autopilot
from .autopilots import personality
from .beacon import UNAUTHENTICATED_SIZE
from .failsafe import Action, FailsafeSettings
from .flightpath import FlightPath, flight_path
from .link import Channel, Clock, Impairments, LinkEndpoint, SimMedium, profile
from .link.airtime import PROFILES
from .mission import (
    MissionError,
    MissionItem,
    ground_offset,
    point_as_segment,
)
from .missionfile import read_mission_file
from .mock_autopilot import Faults, FlightModel, MockAutopilot
from .planner import OffsetSettings
from .replay_fleet import make_fleet
from .replay_vehicles import MockVehicle, Px4SitlVehicle, ReplayVehicle
from .runtime import Companion, CompanionSettings
from .sim_px4 import Px4Build
from .tables import Table, TableError, load_toml

log = logging.getLogger(__name__)
# SIH lock-step speed factor for two PX4 vehicles, their companions and the protocol on 2
# cores: at 10 the crossing resolves but the in-flight crossing's first result came at 105 s
# (33 s at 4x, 40 s at 6x: the companions' CPU time counts 10x over in simulated time with
# two px4 processes taking 1.2 cores) and the drones met at 4 m
PX4_SPEED_MAX = 5.0
VEHICLE_NAMES = {
    ("mock", "px4"): "px4",
    ("mock", "ardupilot"): "ardupilot",
    ("px4-sitl", "px4"): "PX4 SITL",
}
REPORT_RADIUS_M = 50_000.0  # the report's own grid (plain predicate only): any encounter fits
Track = list[tuple[float, float, float, float]]


@dataclass(frozen=True)
class Tracks:
    """What a plot needs beyond the report: flown and baseline trajectories, ground paths."""

    flown: dict[int, Track]
    baseline: dict[int, Track]
    paths: dict[int, list[tuple[int, int]]]


@dataclass(frozen=True)
class Replay:
    report: dict[str, Any]  # what --json prints
    tracks: Tracks


MAX_TIME_SCALE = 10_000.0  # simulated seconds per real second: lossy_sf9 flies at 2000
MAX_LOSS = 0.9  # more loss than this and no run ends: a scenario for nothing


class ScenarioError(TableError):
    """The scenario file is invalid."""


@dataclass(frozen=True)
class DroneSpec:
    id: int
    mission: list[MissionItem]
    home: tuple[float, float, float]
    takeoff_delay_s: float = 0.0
    ardupilot: bool = False
    faults: Faults = field(default_factory=Faults)  # of its mock autopilot
    companion_stop_s: float | None = None  # the companion vanishes at this simulated time
    hold_for_comparisons: bool = True  # on the ground, take-off waits for a running run
    operator: str = "fleet"  # whose certificate it flies with

    @property
    def path(self) -> FlightPath:
        """The ground path the vehicle flies (launch leg from home included)."""
        home = (round(self.home[0] * 1e7), round(self.home[1] * 1e7))
        return flight_path(self.mission, home, ardupilot=self.ardupilot)


@dataclass(frozen=True)
class Scenario:
    name: str
    time_scale: float
    time_limit_s: float
    link_profile: str
    loss: float
    seed: int | None
    drones: list[DroneSpec]
    offset_m: float = 10.0
    cruise_m_s: float = 10.0
    beacon_interval_s: float = 5.0
    grid_radius_m: float = 500.0
    grid_resolution_mm: int = 500
    lookahead_s: float = 60.0
    failsafe: Action = Action.CLIMB
    untrusted_operators: frozenset[str] = frozenset()  # not in the other drones' trust stores
    unknown_peers: UnknownPeers = UnknownPeers.IGNORE

    def trusted_pair(self, a: DroneSpec, b: DroneSpec) -> bool:
        """Both drones deconflict with each other (neither is of an untrusted operator)."""
        return not {a.operator, b.operator} & self.untrusted_operators


def load_scenario(path: str | Path) -> Scenario:
    """Read and check a scenario file whole (:mod:`companion.tables`): every number finite
    and in range, every mission readable, no unknown key."""
    path = Path(path)
    doc = Table(load_toml(path, ScenarioError), str(path), ScenarioError)
    time_scale = doc.number("time_scale", 20.0, low=0.0, above=True)
    if time_scale > MAX_TIME_SCALE:
        raise doc.fail(f"{time_scale:g} is out of range (at most {MAX_TIME_SCALE:g})", "time_scale")
    time_limit_s = doc.number("time_limit_s", 900.0, low=0.0, above=True)
    link = doc.table("link")
    link_profile = link.text("profile", "us915-sf7", list(PROFILES))
    loss = link.number("loss", 0.0, low=0.0, high=MAX_LOSS)
    seed = link.optional_integer("seed", low=0)
    raw_drones = doc.tables("drone", "drone")
    if len(raw_drones) < 2:
        raise doc.fail("at least two [[drone]] tables are needed")
    drones, ids = [], set()
    for raw in raw_drones:
        ident = raw.integer("id", low=1, high=0xFFFE)
        if ident in ids:
            raise raw.fail(f"{ident} is taken by another drone", "id")
        ids.add(ident)
        kind = raw.text("autopilot", "px4", ("px4", "ardupilot"))
        mission_file = raw.text("mission")
        try:
            plan = read_mission_file(path.parent / mission_file)  # errors name the file
        except MissionError as exc:
            raise raw.fail(str(exc)) from None
        try:
            if plan.home is None:
                raise MissionError("the mission file gives no home")
            items = plan.for_autopilot(ardupilot=kind == "ardupilot")
            flight_path(items, plan.home_degE7, ardupilot=kind == "ardupilot")  # jumps valid
        except MissionError as exc:
            raise raw.fail(f"{mission_file}: {exc}") from None
        drones.append(
            DroneSpec(
                ident,
                items,
                plan.home,
                raw.number("takeoff_delay_s", 0.0, low=0.0),
                kind == "ardupilot",
                hold_for_comparisons=raw.flag("hold_for_comparisons", True),
                operator=raw.text("operator", "fleet"),
            )
        )
    failsafe = doc.text("failsafe", "climb", [a.value for a in Action])
    untrusted = doc.strings("untrusted_operators")
    if not {d.operator for d in drones} - set(untrusted):
        raise doc.fail("every operator is untrusted", "untrusted_operators")
    policy = doc.text("unknown_peers", "ignore", [p.value for p in UnknownPeers])
    scenario = Scenario(
        name=path.stem,
        time_scale=time_scale,
        time_limit_s=time_limit_s,
        link_profile=link_profile,
        loss=loss,
        seed=seed,
        drones=drones,
        offset_m=doc.number("offset_m", 10.0, low=0.0, above=True),
        cruise_m_s=doc.number("cruise_m_s", 10.0, low=0.0, above=True),
        beacon_interval_s=doc.number("beacon_interval_s", 5.0, low=0.0, above=True),
        grid_radius_m=doc.number("grid_radius_m", 500.0, low=0.0, above=True),
        grid_resolution_mm=doc.integer("grid_resolution_mm", 500, low=1),
        lookahead_s=doc.number("lookahead_s", 60.0, low=0.0),
        failsafe=Action(failsafe),
        untrusted_operators=frozenset(untrusted),
        unknown_peers=UnknownPeers(policy),
    )
    doc.finish()
    return scenario


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _enu(a: tuple[float, float, float], ref: tuple[float, float]) -> tuple[float, float, float]:
    return (*ground_offset(ref[0], ref[1], a[0], a[1]), a[2])


def _fly_offline(scenario: Scenario) -> dict[int, list[tuple[float, float, float, float]]]:
    """The baseline: the same missions and schedule through the same flight model, no radio."""
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
    while t < scenario.time_limit_s:
        for d in scenario.drones:
            mock = mocks[d.id]
            if d.id not in started and t >= d.takeoff_delay_s:
                mock.take_off()
                started.add(d.id)
            mock.advance(dt)
        t += dt
        if len(started) == len(mocks) and not any(m.mission_running for m in mocks.values()):
            break
    return {k: m.trajectory for k, m in mocks.items()}


async def run_replay(
    scenario: Scenario,
    *,
    progress: bool = False,
    px4: Px4Build | None = None,
    px4_speed_max: float = PX4_SPEED_MAX,
) -> Replay:
    """Fly ``scenario``: mock autopilots, or PX4 SITL vehicles from the build ``px4`` (their
    speed factor, and so the replay's time scale, at most ``px4_speed_max``)."""
    ts = scenario.time_scale if px4 is None else min(scenario.time_scale, px4_speed_max)
    clock = Clock(ts)
    medium = SimMedium(Channel(Impairments(loss=scenario.loss), scenario.seed), clock)
    link = profile(scenario.link_profile)
    mocks: dict[int, ReplayVehicle] = {}
    companions: dict[int, Companion] = {}
    vanished: dict[int, Companion] = {}
    autopilots: list[Autopilot] = []
    flight = FlightModel(cruise_m_s=scenario.cruise_m_s, time_scale=ts, rate_hz=20.0)
    origin = time.monotonic()  # simulated time zero for every vehicle and the schedule
    state = tempfile.TemporaryDirectory(prefix="replay-state-")
    fleet = make_fleet(
        [(d.id, d.operator) for d in scenario.drones],
        Path(state.name),
        untrusted=scenario.untrusted_operators,
        unknown=scenario.unknown_peers,
    )

    def say(message: str) -> None:
        if progress:
            print(f"  ... {message}", file=sys.stderr, flush=True)

    try:
        for d in scenario.drones:
            vehicle: ReplayVehicle
            if px4 is None:
                vehicle = MockVehicle(
                    d.mission,
                    d.home,
                    ardupilot=d.ardupilot,
                    flight=flight,
                    faults=d.faults,
                    bind_port=free_udp_port(),
                    send_port=free_udp_port(),
                )
            else:
                if d.ardupilot:
                    raise ScenarioError(f"drone {d.id}: PX4 SITL cannot fly an ArduPilot drone")
                vehicle = Px4SitlVehicle(
                    px4, d.mission, d.home, speed_factor=ts, cruise_m_s=scenario.cruise_m_s
                )
            mocks[d.id] = vehicle
            await vehicle.start(origin)
            ap = await Autopilot.connect(vehicle.api_url, personality=personality(d.ardupilot))
            autopilots.append(ap)
            settings = CompanionSettings(
                node=d.id,
                autopilot_url=vehicle.api_url,
                ardupilot=d.ardupilot,
                offset=OffsetSettings(offset_m=scenario.offset_m),
                beacon_interval_s=scenario.beacon_interval_s,
                grid_radius_m=scenario.grid_radius_m,
                grid_resolution_mm=scenario.grid_resolution_mm,
                lookahead_s=scenario.lookahead_s,
                cruise_m_s=scenario.cruise_m_s,
                failsafe=FailsafeSettings(action=scenario.failsafe),
            )
            endpoint = LinkEndpoint(d.id, medium.attach(d.id), link, clock=clock)
            companions[d.id] = Companion(settings, endpoint, ap, fleet[d.id])
            await companions[d.id].start()
            say(f"drone {d.id}: {vehicle.kind} vehicle, MAVSDK and companion up")
        origin = time.monotonic()  # simulated time zero: everything is up
        for mock in mocks.values():
            mock.restart_clock(origin)
        for companion in companions.values():
            companion.epoch = clock.now()
        started: set[int] = set()
        while True:
            sim = (time.monotonic() - origin) * ts
            for d in scenario.drones:
                gone = companions.get(d.id)
                if d.companion_stop_s is not None and sim >= d.companion_stop_s and gone:
                    await gone.stop()  # the peer vanishes: its radio goes silent
                    vanished[d.id] = companions.pop(d.id)
                    say(f"t={sim:.0f} s: drone {d.id}'s companion vanishes")
                waiting = (
                    d.hold_for_comparisons and d.id in companions and companions[d.id].comparing
                )
                if d.id not in started and sim >= d.takeoff_delay_s and not waiting:
                    # a drone about to take off waits for its comparison to finish
                    await mocks[d.id].take_off()
                    started.add(d.id)
                    say(f"t={sim:.0f} s: drone {d.id} takes off")
            done = len(started) == len(mocks) and not any(m.flying for m in mocks.values())
            if done or sim >= scenario.time_limit_s:
                break
            await asyncio.sleep(0.01)
        say(f"t={sim:.0f} s: {'all missions flown' if done else 'time limit'}")
    finally:
        for companion in companions.values():
            await companion.stop()
        for ap in autopilots:  # MAVSDK off the vehicle before the harness reads its mission
            await ap.close()
        held = {}
        for k, vehicle in mocks.items():
            try:
                held[k] = await vehicle.held_mission()
            except Exception as exc:  # the report says "other", the log says why
                log.warning("drone %d: the mission held at the end is unknown: %s", k, exc)
                held[k] = []
        for vehicle in mocks.values():
            await vehicle.stop()
        state.cleanup()
    baseline = _fly_offline(scenario)
    return Replay(
        _report(scenario, mocks, held, companions | vanished, baseline, done, ts),
        Tracks(
            {k: m.trajectory for k, m in mocks.items()},
            baseline,
            {d.id: d.path.points for d in scenario.drones},
        ),
    )


TIMELINE = (
    "run_started",
    "result",
    "run_failed",
    "uploaded",
    "precautionary",
    "hold",
    "resumed",
    "setup_renewed",
)


def _closest(
    a: Track, b: Track
) -> tuple[float, float, tuple[float, float, float], tuple[float, float, float]]:
    """(distance, time, point a, point b) of the closest approach of two trajectories."""
    best: tuple[float, float, tuple[float, float, float], tuple[float, float, float]] = (
        math.inf,
        0.0,
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
    )
    if not a or not b:
        return best
    j = 0
    for t, lat, lon, alt in a:
        while j + 1 < len(b) and abs(b[j + 1][0] - t) <= abs(b[j][0] - t):
            j += 1
        d = math.dist(_enu((lat, lon, alt), (a[0][1], a[0][2])), _enu(b[j][1:], (a[0][1], a[0][2])))
        if d < best[0]:
            best = (d, t, (lat, lon, alt), b[j][1:])
    return best


def _acted(c: Companion, peer: int, until: float) -> bool:
    """Did this companion act on its pair with ``peer`` before ``until``: a precautionary
    action for it, or a verified edit that flies a segment a result flagged for it higher?"""
    if any(
        e.kind == "precautionary" and e.detail.get("peer") == peer and e.t <= until
        for e in c.events
    ):
        return True
    flagged = {
        k
        for e in c.events
        if e.kind == "result" and e.detail.get("peer") == peer and e.t <= until
        for k in e.detail.get("flagged", [])
    }
    return any(
        e.kind == "uploaded"
        and e.t <= until
        and e.detail.get("verified")
        and flagged & {int(k) for k in e.detail.get("levels", {})}
        for e in c.events
    )


def _report(
    scenario: Scenario,
    mocks: dict[int, ReplayVehicle],
    held: dict[int, list[MissionItem]],
    companions: dict[int, Companion],
    baseline: dict[int, Track],
    finished: bool,
    time_scale: float,
) -> dict[str, Any]:
    first = scenario.drones[0]
    grid = GridSpec.geo(
        round(first.home[0] * 1e7), round(first.home[1] * 1e7), radius_m=REPORT_RADIUS_M
    )
    paths = {  # a hover is a point, as Bob sends it
        d.id: point_as_segment(grid.project_path(d.path.points, checked=False))
        for d in scenario.drones
    }
    drones, false_alarms, precautions = [], 0, 0
    specs = {d.id: d for d in scenario.drones}
    for d in scenario.drones:
        c = companions[d.id]
        others = [
            p for k, p in paths.items() if k != d.id and scenario.trusted_pair(d, specs[k])
        ]  # (a drone nobody deconflicts with has nothing to flag)
        hits = [path_hits(paths[d.id], o) for o in others]
        plain = [any(h) for h in zip(*hits, strict=True)] if hits else [False] * d.path.segments
        flagged = sorted(c.flagged)
        false_alarms += sum(1 for k in flagged if k < len(plain) and not plain[k])
        precautionary = [
            {"t_s": round(e.t, 1), **e.detail} for e in c.events if e.kind == "precautionary"
        ]
        precautions += len(precautionary)
        stats = c.endpoint.stats
        run_auth = sum(
            e.detail.get("auth_bytes", 0) for e in c.events if e.kind in ("result", "answered")
        )
        drones.append(
            {
                "id": d.id,
                "operator": d.operator,
                "autopilot": "ardupilot" if d.ardupilot else "px4",
                "vehicle": mocks[d.id].kind,
                "segments": d.path.segments,
                "conflicting_segments": [k for k, h in enumerate(plain) if h],
                "flagged_segments": flagged,
                "levels": {str(k): v for k, v in sorted(c.levels.items())},
                "edits": [e.detail for e in c.events if e.kind == "uploaded"],
                "edit": _edit_status(c),
                "runs_unfinished": _unfinished(c),
                "runs": [e.detail | {"t_s": round(e.t, 1)} for e in c.events if e.kind == "result"],
                "failures": [e.detail | {"kind": e.kind} for e in c.events if "failed" in e.kind],
                "precautionary": precautionary,
                "timeline": [
                    {"t_s": round(e.t, 1), "kind": e.kind}
                    | {k: v for k, v in e.detail.items() if k in ("peer", "phase", "why")}
                    for e in c.events
                    if e.kind in TIMELINE
                ],
                "bytes_sent": stats.bytes_sent,
                "frames_sent": stats.frames_sent,
                "airtime_s": round(stats.airtime_s, 3),
                "auth": {  # what authentication costs on the radio (companion.auth)
                    "run_bytes": run_auth,  # key exchange and tags of finished runs
                    "beacon_bytes": c.beacon_bytes,  # beacon payloads sent, all kinds
                    "beacons": dict(c.beacons_sent),
                    # beyond unauthenticated 24-byte position beacons (payload bytes)
                    "beacon_added_bytes": c.beacon_bytes
                    - UNAUTHENTICATED_SIZE * (c.beacons_sent["signed"] + c.beacons_sent["tagged"]),
                },
                "untrusted_heard": [e.detail["drone"] for e in c.events if e.kind == "untrusted"],
                "beacons_rejected": dict(c.rejected),
                "max_altitude_m_amsl": round(
                    max((alt for *_, alt in mocks[d.id].trajectory), default=0.0), 2
                ),
                "vehicle_holds": _holds(held[d.id], d.mission, c.mission, d.ardupilot),
            }
        )
    pairs, resolved, conflicts, untrusted = [], 0, 0, 0
    ids = [d.id for d in scenario.drones]
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            crossing = any(path_hits(paths[a], paths[b]))
            with_companion, when, _, _ = _closest(mocks[a].trajectory, mocks[b].trajectory)
            without, _, _, _ = _closest(baseline[a], baseline[b])
            trusted = scenario.trusted_pair(specs[a], specs[b])
            conflict = crossing and without < scenario.offset_m
            # each vehicle holds its altitude to within its own accuracy
            tolerance = mocks[a].altitude_accuracy_m + mocks[b].altitude_accuracy_m
            # a pair with an operator outside the trust store is deliberately not deconflicted
            acted = trusted and (_acted(companions[a], b, when) or _acted(companions[b], a, when))
            ok = conflict and acted and (with_companion >= scenario.offset_m - tolerance)
            untrusted += conflict and not trusted
            conflicts += conflict and trusted
            resolved += ok
            pairs.append(
                {
                    "drones": [a, b],
                    "trusted": trusted,
                    "paths_cross": crossing,
                    "conflict": conflict,
                    "acted": acted,
                    "resolved": ok,
                    "closest_approach_m": round(with_companion, 2),
                    "closest_approach_t_s": round(when, 1),
                    "closest_approach_baseline_m": round(without, 2),
                    "resolved_tolerance_m": tolerance,
                }
            )
    report: dict[str, Any] = {
        "scenario": scenario.name,
        "link": {"profile": scenario.link_profile, "loss": scenario.loss, "seed": scenario.seed},
        "time_scale": time_scale,
        "finished": finished,
        "offset_m": scenario.offset_m,
        "drones": drones,
        "pairs": pairs,
        "conflicts": conflicts,
        "conflicts_resolved": resolved,
        "untrusted_conflicts": untrusted,  # with drones outside the trust stores: not handled
        "precautionary_actions": precautions,
        "false_alarms": false_alarms,
    }
    report["problems"] = problems(report)
    report["notes"] = notes(report)
    report["ok"] = not report["problems"]
    return report


# Companion events after which the drone did not fly what it should have: a replay with one
# has failed, whatever the separations say.
FAILED_EVENTS = frozenset(
    {"plan_failed", "upload_failed", "hold_failed", "resume_failed", "mission_invalid"}
)


def _edit_status(c: Companion) -> str:
    """What became of the drone's mission: "verified" (an edit uploaded and read back the
    same), "failed" (an edit was needed and did not land) or "not needed"."""
    if any(e.kind in ("plan_failed", "upload_failed") for e in c.events):
        return "failed"
    return "verified" if any(e.kind == "uploaded" for e in c.events) else "not needed"


def _unfinished(c: Companion) -> int:
    """Runs as Alice that started and neither gave a result nor failed (cut by the end)."""
    open_runs = 0
    for e in c.events:
        if e.kind == "run_started":
            open_runs += 1
        elif e.kind in ("result", "run_failed", "yielded", "setup_renewed") and open_runs:
            open_runs -= 1
    return open_runs


def notes(report: dict[str, Any]) -> list[str]:
    """What the summary states without failing the replay: precautionary actions, runs that
    failed (and were retried), runs the end of the replay cut off (every mission flown)."""
    out = []
    for d in report["drones"]:
        if d["precautionary"]:
            out.append(f"drone {d['id']}: {len(d['precautionary'])} precautionary action(s)")
        failed = [f for f in d["failures"] if f["kind"] not in FAILED_EVENTS]
        if failed:
            kinds = ", ".join(sorted({f["kind"].replace("_", " ") for f in failed}))
            out.append(f"drone {d['id']}: {len(failed)} run(s) ended without a result ({kinds})")
        if d["runs_unfinished"]:
            out.append(f"drone {d['id']}: {d['runs_unfinished']} run(s) still under way at the end")
    return out


def problems(report: dict[str, Any]) -> list[str]:
    """Everything that makes a replay a failure, one line each (empty: it succeeded)."""
    out = []
    if not report["finished"]:
        out.append("the time limit ended the replay before every mission was flown")
    for d in report["drones"]:
        for failure in d["failures"]:
            if failure["kind"] in FAILED_EVENTS:
                why = failure.get("error") or failure.get("why") or ""
                out.append(f"drone {d['id']}: {failure['kind'].replace('_', ' ')}: {why}")
    for p in report["pairs"]:
        if p["conflict"] and p["trusted"] and not p["resolved"]:
            a, b = p["drones"]
            out.append(
                f"drones {a}-{b}: conflict NOT resolved (closest approach "
                f"{p['closest_approach_m']:.1f} m, offset {report['offset_m']:g} m)"
            )
    if report["false_alarms"]:
        out.append(f"{report['false_alarms']} segment(s) flagged that do not cross (false alarm)")
    return out


def _holds(
    held: list[MissionItem],
    original: list[MissionItem],
    edited: list[MissionItem],
    ardupilot: bool,
) -> str:
    """Which mission the vehicle ended with: the original, the companion's edit, or neither
    (compared by what the autopilot means: PX4 reads frame 3 back as 6, ...)."""
    same_meaning = personality(ardupilot).same_meaning

    def same(a: list[MissionItem], b: list[MissionItem]) -> bool:
        return len(a) == len(b) and all(same_meaning(y, x) for x, y in zip(a, b, strict=True))

    if same(held, original):
        return "original"
    return "edited" if same(held, edited) else "other"


def format_report(report: dict[str, Any]) -> str:
    """The replay as text: what each drone did, each pair's separation, and every problem."""
    lines = [
        f"Replay {report['scenario']} over {report['link']['profile']} "
        f"(loss {report['link']['loss']:.0%}), time scale {report['time_scale']}x"
        + ("" if report["finished"] else " -- TIME LIMIT REACHED before every mission was flown")
        + ":"
    ]
    for d in report["drones"]:
        if d["edit"] == "verified":
            levels = ", ".join(
                f"{k} (+{v * report['offset_m']:.0f} m)" for k, v in d["levels"].items()
            )
            what = f"flies segments {levels or 'none'} higher (upload verified)"
        elif d["edit"] == "failed":
            what = "needed an edit that FAILED, flies its original altitudes"
        else:
            what = "kept its altitude (no edit needed)"
        if d["precautionary"]:
            what += f"; {len(d['precautionary'])} precautionary action(s)"
        if d["failures"]:
            kinds = sorted({f["kind"] for f in d["failures"]})
            what += f"; {len(d['failures'])} failure(s): {', '.join(kinds)}"
        if d["runs_unfinished"]:
            what += f"; {d['runs_unfinished']} run(s) never finished"
        if d["untrusted_heard"]:
            what += f"; ignored {len(d['untrusted_heard'])} untrusted drone(s)"
        auth = d["auth"]
        lines.append(
            f"  drone {d['id']} ({VEHICLE_NAMES[d['vehicle'], d['autopilot']]}, "
            f"{d['operator']}): {what}; radio {d['bytes_sent']} B in {d['frames_sent']} frames, "
            f"{d['airtime_s']:.1f} s airtime (authentication adds {auth['run_bytes']} B to "
            f"runs, {auth['beacon_added_bytes']} B to beacons)"
        )
    for p in report["pairs"]:
        a, b = p["drones"]
        if not p["trusted"]:
            lines.append(
                f"  drones {a}-{b}: not deconflicted (an operator outside the trust store); "
                f"closest approach {p['closest_approach_m']:.1f} m"
            )
            continue
        verdict = (
            "resolved" if p["resolved"] else "NOT resolved" if p["conflict"] else "no conflict"
        )
        lines.append(
            f"  drones {a}-{b}: closest approach {p['closest_approach_baseline_m']:.1f} m "
            f"without the companion, {p['closest_approach_m']:.1f} m with it "
            f"(t = {p['closest_approach_t_s']:.0f} s): {verdict}"
        )
    lines.append(
        f"  conflicts resolved {report['conflicts_resolved']}/{report['conflicts']}, "
        f"precautionary actions {report['precautionary_actions']}, "
        f"false alarms {report['false_alarms']}"
        + (
            f"; {report['untrusted_conflicts']} conflict(s) with untrusted drones NOT handled"
            if report["untrusted_conflicts"]
            else ""
        )
    )
    if report.get("notes"):
        lines.append("Notes:")
        lines.extend(f"  - {line}" for line in report["notes"])
    if report["problems"]:
        lines.append(f"FAILED ({len(report['problems'])} problem(s)):")
        lines.extend(f"  - {line}" for line in report["problems"])
    else:
        lines.append("OK: every mission flown, every conflict resolved by a verified action")
    return "\n".join(lines)


MARKERS = {
    "run_started": ("^", "run started"),
    "result": ("o", "result"),
    "uploaded": ("*", "edit verified"),
    "precautionary": ("X", "precaution"),
}


PLOT_FORMATS = ("png", "pdf", "svg")


def plot_report(replay: Replay, out: str | Path) -> None:
    """PNG, PDF or SVG (by ``out``'s ending): ground tracks (planned, flown, direction,
    closest approaches), the distance of every pair over time with the runs' moments marked,
    and altitudes over the flight window."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    kind = out.suffix.lower().lstrip(".")
    if kind not in PLOT_FORMATS:
        raise ScenarioError(f"{out}: a plot is {', '.join(PLOT_FORMATS)} (by the file's ending)")
    report, tracks = replay.report, replay.tracks
    ref = next(iter(tracks.paths.values()))[0]
    ref_deg = (ref[0] / 1e7, ref[1] / 1e7)

    def en(lat: float, lon: float) -> tuple[float, float]:
        north, east, _ = _enu((lat, lon, 0.0), ref_deg)
        return east, north

    fig, (ground, gap, height) = plt.subplots(1, 3, figsize=(19, 6))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {d["id"]: colours[n % len(colours)] for n, d in enumerate(report["drones"])}
    for drone in report["drones"]:
        ident, c = drone["id"], colour[drone["id"]]
        path = [en(lat / 1e7, lon / 1e7) for lat, lon in tracks.paths[ident]]
        ground.plot(*zip(*path, strict=True), "o--", color=c, lw=0.8, ms=3, alpha=0.6)
        for k in drone["flagged_segments"]:
            (x0, y0), (x1, y1) = path[k], path[k + 1]
            ground.plot([x0, x1], [y0, y1], color="red", lw=6, alpha=0.25)
        flown = [en(lat, lon) for _, lat, lon, _ in tracks.flown[ident]]
        if len(flown) > 1:
            ground.plot(*zip(*flown, strict=True), color=c, lw=1.6, label=f"drone {ident} flown")
            for tail, head in _arrows(flown, ARROWS):
                ground.annotate(
                    "",
                    head,
                    tail,
                    arrowprops={"arrowstyle": "-|>", "color": c, "mutation_scale": 18, "lw": 0},
                )
    for pair in report["pairs"]:
        a, b = pair["drones"]
        _, t, pa, pb = _closest(tracks.flown[a], tracks.flown[b])
        if math.isfinite(pair["closest_approach_m"]):
            (xa, ya), (xb, yb) = en(pa[0], pa[1]), en(pb[0], pb[1])
            ground.plot([xa, xb], [ya, yb], "k:", lw=1)
            ground.plot([xa, xb], [ya, yb], "kx", ms=8)
            ground.annotate(
                f"{a}-{b}: {pair['closest_approach_m']:.1f} m at {t:.0f} s", (xa, ya), fontsize=7
            )
    ground.plot([], [], color="red", lw=6, alpha=0.25, label="flagged segments")
    ground.plot([], [], "kx", label="closest approach")
    ground.set(xlabel="east (m)", ylabel="north (m)", title=f"{report['scenario']}: ground tracks")
    ground.set_aspect("equal", adjustable="datalim")
    ground.legend(loc="best", fontsize=7)

    for pair in report["pairs"]:
        a, b = pair["drones"]
        for which, style in ((tracks.flown, "-"), (tracks.baseline, ":")):
            series = _separation(which[a], which[b])
            if series:
                gap.plot(
                    *zip(*series, strict=True),
                    style,
                    lw=1.4 if style == "-" else 1,
                    label=f"{a}-{b} {'with' if style == '-' else 'without'} companion",
                )
        for drone in report["drones"]:
            if drone["id"] not in (a, b):
                continue
            other = b if drone["id"] == a else a
            for event in drone["timeline"]:
                if event["kind"] in MARKERS and event.get("peer", other) == other:
                    marker, _ = MARKERS[event["kind"]]
                    gap.axvline(event["t_s"], color=colour[drone["id"]], lw=0.4, alpha=0.5)
                    gap.plot(
                        event["t_s"], 0, marker, color=colour[drone["id"]], ms=8, clip_on=False
                    )
    for marker, label in MARKERS.values():
        gap.plot([], [], marker, color="grey", label=label)
    gap.axhline(report["offset_m"], color="red", lw=0.8, ls="--", label="offset")
    gap.set(xlabel="simulated time (s)", ylabel="3-D distance (m)", title="distance of each pair")
    gap.set_yscale("symlog", linthresh=20)
    gap.legend(loc="best", fontsize=7)

    for drone in report["drones"]:
        ident, c = drone["id"], colour[drone["id"]]
        for which, style, label in (
            (tracks.baseline, "--", "planned"),
            (tracks.flown, "-", "flown"),
        ):
            track = which[ident]
            height.plot(
                [p[0] for p in track],
                [p[3] for p in track],
                style,
                color=c,
                lw=1 if style == "--" else 1.5,
                label=f"drone {ident} {label}",
            )
    window = _flight_window(tracks.flown)
    if window is not None:  # hours on the ground waiting for airtime would hide the flight
        height.set_xlim(*window)
    height.set(
        xlabel="simulated time (s)",
        ylabel="altitude AMSL (m)",
        title="altitude while flying",
    )
    height.legend(loc="best", fontsize=7)
    fig.tight_layout()
    tmp = out.with_name(f".{out.name}.tmp")
    try:
        fig.savefig(tmp, dpi=100, format=kind)
        tmp.replace(out)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)


def _flight_window(flown: dict[int, Track], margin_s: float = 30.0) -> tuple[float, float] | None:
    """From the first take-off to the last landing (any drone 2 m above where it started)."""
    airborne = [
        t for track in flown.values() if track for t, *_, alt in track if alt > track[0][3] + 2.0
    ]
    if not airborne:
        return None
    return max(min(airborne) - margin_s, 0.0), max(airborne) + margin_s


ARROWS = 6  # direction arrows along each flown track


def _arrows(
    points: list[tuple[float, float]], count: int
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """(tail, head) of ``count`` short arrows spread evenly by distance along ``points`` (a
    track that holds still for minutes still gets its arrows where it moves)."""
    steps = [math.dist(p, q) for p, q in itertools.pairwise(points)]
    length = sum(steps)
    if length <= 0:
        return []
    out, walked, k = [], 0.0, 0
    for n in range(count):
        goal = length * (n + 0.5) / count
        while k < len(steps) - 1 and walked + steps[k] < goal:
            walked += steps[k]
            k += 1
        (x0, y0), (x1, y1) = points[k], points[k + 1]
        if steps[k] == 0:
            continue
        f = (goal - walked) / steps[k]
        dx, dy = (x1 - x0) / steps[k], (y1 - y0) / steps[k]
        x, y = x0 + f * (x1 - x0), y0 + f * (y1 - y0)
        size = length * 0.01
        out.append(((x - dx * size, y - dy * size), (x + dx * size, y + dy * size)))
    return out


def _separation(a: Track, b: Track) -> list[tuple[float, float]]:
    """3-D distance of two trajectories over time (b sampled at a's times)."""
    if not a or not b:
        return []
    out = []
    j = 0
    ref = (a[0][1], a[0][2])
    for t, lat, lon, alt in a[:: max(1, len(a) // 2000)]:
        while j + 1 < len(b) and abs(b[j + 1][0] - t) <= abs(b[j][0] - t):
            j += 1
        out.append((t, math.dist(_enu((lat, lon, alt), ref), _enu(b[j][1:], ref))))
    return out
