"""What a replay measured: each drone's runs, edits and radio costs from its companion's
events, each pair's separation with the companions and without them (the baseline), and
whether a conflict was resolved by the companions' action -- made into the typed
:class:`~companion.sim.report.ReplayReport`.

A pair is in *conflict* when, without the companions, the two drones came inside each other's
protected volume: horizontally closer than ``separation_m`` and vertically closer than
``vertical_separation_m`` at the same moment, both in the air (whether their tracks cross or
not).  It is *resolved* when a companion acted for it (a precaution, or a verified edit flying
higher a segment a run flagged for that peer) before they would have met, either drone flew
differently from its baseline (:data:`DEVIATED_M`), and with the companions they never came
inside (vertically: less the vehicles' altitude accuracy).  An edit or precaution for a pair
that never came inside without the companions is a *false alarm*; a pair the companions
brought closer, and inside, with either drone flying differently, is *made worse*.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

from companion.app.runtime import Companion
from companion.events import RUN_ENDS, Answered, Precaution, RunResult, Stranger, Uploaded
from companion.events import EventKind as K
from companion.mission.items import MissionItem, point_as_segment
from companion.mission.personalities import personality
from companion.neighbours.beacon import UNAUTHENTICATED_SIZE, BeaconKind
from companion.sim.report import (
    AuthCost,
    DroneReport,
    EditStatus,
    LinkInfo,
    PairReport,
    ReplayReport,
)
from companion.sim.scenario import DroneSpec, Scenario
from companion.sim.vehicles import ReplayVehicle, Track
from protocol.geo.geodesy import ground_offset, metres_per_degree
from protocol.geo.geometry import Point, path_hits
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import Route, Separation, route_hits

REPORT_RADIUS_M = 50_000.0  # the report's own grid (plain predicate only): any encounter fits


def enu(a: tuple[float, float, float], ref: tuple[float, float]) -> tuple[float, float, float]:
    """(north, east, up) metres of ``a`` (lat, lon, alt) from ``ref`` (lat, lon)."""
    return (*ground_offset(ref[0], ref[1], a[0], a[1]), a[2])


TIMELINE = frozenset(
    {
        K.RUN_STARTED,
        K.RESULT,
        K.RUN_FAILED,
        K.PEER_BUSY,
        K.UPLOADED,
        K.PRECAUTIONARY,
        K.HOLD,
        K.RESUMED,
        K.RETIMED,
        K.SETUP_RENEWED,
    }
)


class Local:
    """Tracks on the tangent plane at ``ref`` (lat, lon): (t, north, east, up) for each
    sample, projected once per track (a replay's pairs share them; the tangent plane's
    distortion is under a millimetre within a few kilometres of ``ref``)."""

    def __init__(self, ref: tuple[float, float]) -> None:
        self.ref = ref
        self._done: dict[int, tuple[Track, list[tuple[float, float, float, float]]]] = {}

    def of(self, track: Track) -> list[tuple[float, float, float, float]]:
        kept = self._done.get(id(track))
        if kept is not None and kept[0] is track:
            return kept[1]
        lat0, lon0 = self.ref
        out = [(t, *ground_offset(lat0, lon0, lat, lon), alt) for t, lat, lon, alt in track]
        self._done[id(track)] = (track, out)
        return out


def _aligned(
    a: Track, b: Track, local: Local | None = None
) -> list[tuple[int, int, float, float, float]]:
    """(index in a, index in b, horizontal m, vertical m, dt) at each sample of ``a``,
    against ``b`` at the nearest time (both tracks are sampled finely in simulated time)."""
    out: list[tuple[int, int, float, float, float]] = []
    if not a or not b:
        return out
    local = local or Local((a[0][1], a[0][2]))
    la, lb = local.of(a), local.of(b)
    j = 0
    previous = a[0][0]
    for i, (t, north, east, up) in enumerate(la):
        while j + 1 < len(lb) and abs(lb[j + 1][0] - t) <= abs(lb[j][0] - t):
            j += 1
        q = lb[j]
        out.append((i, j, math.hypot(north - q[1], east - q[2]), abs(up - q[3]), t - previous))
        previous = t
    return out


def intrusion(
    a: Track,
    b: Track,
    horizontal_m: float,
    vertical_m: float,
    local: Local | None = None,
    grounds: tuple[float, float] | None = None,
) -> tuple[float, float]:
    """Seconds the two were inside each other's protected volume (horizontally closer than
    ``horizontal_m`` and vertically than ``vertical_m``), and when they first were (inf:
    never).  With ``grounds`` (each one's home altitude, AMSL) only while both are in the air:
    two drones parked on pads a few metres apart are no traffic."""
    inside, first = 0.0, math.inf
    low_a, low_b = (-math.inf, -math.inf) if grounds is None else (g + AIRBORNE_M for g in grounds)
    for i, j, h, v, dt in _aligned(a, b, local):
        if h < horizontal_m and v < vertical_m and a[i][3] > low_a and b[j][3] > low_b:
            inside += dt
            first = min(first, a[i][0])
    return inside, first


def deviation(flown: Track, baseline: Track, local: Local | None = None) -> float:
    """The farthest a drone's flown track came from its baseline's at the same moment
    (metres, 3-D): what tells a drone that flew differently (a raise, a hold) from one
    whose replay differs from its baseline only by the simulation's timing."""
    return max((math.hypot(h, v) for *_, h, v, _ in _aligned(flown, baseline, local)), default=0.0)


def separation(a: Track, b: Track, local: Local | None = None) -> list[tuple[float, float]]:
    """(t, 3-D distance) at each sample of ``a``, against ``b`` at the nearest time."""
    return [(a[i][0], math.hypot(h, v)) for i, _, h, v, _ in _aligned(a, b, local)]


def closest(
    a: Track, b: Track, local: Local | None = None
) -> tuple[float, float, tuple[float, float, float], tuple[float, float, float]]:
    """(distance, time, point a, point b) of the closest approach of two trajectories."""
    best: tuple[float, float, tuple[float, float, float], tuple[float, float, float]] = (
        math.inf,
        0.0,
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
    )
    found = min(_aligned(a, b, local), key=lambda s: math.hypot(s[2], s[3]), default=None)
    if found is None:
        return best
    i, j, h, v, _ = found
    return math.hypot(h, v), a[i][0], a[i][1:], b[j][1:]


AIRBORNE_M = 0.5  # above its home: in the air
# A drone's flown track this far from its baseline's at the same moment flew differently (a
# raise is 10 m, a hold more); less is the simulation's own timing: the replay's vehicles
# step at 5 Hz and its baseline's at 10 Hz, and a take-off command lands between two steps
# (0.2 s at 8 m/s: 1.6 m; pairs closing head-on differed by 2-3 m in closest approach
# with neither drone flying anything but its original mission on time)
DEVIATED_M = 5.0
FAR_M = 500.0  # a busy sky's pairs that never came this close are not compared exactly
SCREEN_FROM = 10  # drones: a replay with more has its far pairs screened out


class Screen:
    """Each track once per second, on a flat projection about ``ref`` (lat, lon): a busy
    sky's far pairs told apart in one pass each instead of a geodesic per sample.  Its
    closest approach is within the distance two drones close in a second, and the flat
    projection's error (about a metre at 3 km from ``ref``), of the exact one."""

    def __init__(self, ref: tuple[float, float]) -> None:
        self.ref = ref
        self._north, self._east = metres_per_degree(ref[0])  # the project's Earth model
        self._seconds: dict[int, tuple[Track, dict[int, tuple[float, float, float]]]] = {}

    def _of(self, track: Track) -> dict[int, tuple[float, float, float]]:
        kept = self._seconds.get(id(track))
        if kept is not None and kept[0] is track:
            return kept[1]
        north, east = self._north, self._east
        out: dict[int, tuple[float, float, float]] = {}
        for t, lat, lon, alt in track:
            out.setdefault(int(t), (lat * north, lon * east, alt))
        self._seconds[id(track)] = (track, out)
        return out

    def closest(self, a: Track, b: Track) -> float:
        """Closest approach (metres, 3-D) at the whole seconds both tracks have."""
        sa, sb = self._of(a), self._of(b)
        if len(sa) > len(sb):
            sa, sb = sb, sa
        best = math.inf
        for t, (y, x, z) in sa.items():
            q = sb.get(t)
            if q is not None:
                d = (y - q[0]) ** 2 + (x - q[1]) ** 2 + (z - q[2]) ** 2
                best = min(best, d)
        return math.sqrt(best)


def _acted(c: Companion, peer: int, until: float, *, clear_of: bool = True) -> bool:
    """Did this companion act on its pair with ``peer`` before ``until``: a precautionary
    action for it, a verified edit that flies a segment a result flagged for it higher, or
    a verified edit whose raises were chosen clear of its altitudes (a raise for a third
    drone that keeps out of a peer the runs found clear of the unraised path; not with
    ``clear_of`` False: keeping clear of a peer is no alarm about it)?"""
    before = [e.payload for e in c.events if e.t <= until]
    if any(isinstance(p, Precaution) and p.peer == peer for p in before):
        return True
    flagged = {k for p in before if isinstance(p, RunResult) and p.peer == peer for k in p.flagged}
    return any(
        isinstance(p, Uploaded)
        and p.verified
        and (flagged & {int(k) for k in p.raises} or (clear_of and peer in p.clear_of))
        for p in before
    )


def build_report(
    scenario: Scenario,
    mocks: dict[int, ReplayVehicle],
    held: dict[int, list[MissionItem]],
    companions: dict[int, Companion],
    baseline: dict[int, Track],
    finished: bool,
    time_scale: float,
    *,
    virtual: bool = False,
) -> ReplayReport:
    """The report of a replay (judged: problems and notes filled in)."""
    first = scenario.drones[0]
    grid = GridSpec.geo(
        round(first.home[0] * 1e7), round(first.home[1] * 1e7), radius_m=REPORT_RADIUS_M
    )
    paths = {  # a hover is a point, as Bob sends it
        d.id: tuple(point_as_segment(grid.project_path(d.path.points, checked=False)))
        for d in scenario.drones
    }
    specs = {d.id: d for d in scenario.drones}
    capsule = Separation(math.ceil(scenario.separation_m * 1000 / grid.resolution_mm))
    drones = []
    for d in scenario.drones:
        others = [
            p for k, p in paths.items() if k != d.id and scenario.trusted_pair(d, specs[k])
        ]  # (a drone nobody deconflicts with has nothing to flag)
        hits = [route_hits(Route(paths[d.id]), Route(o), capsule) for o in others]
        plain = [any(h) for h in zip(*hits, strict=True)] if hits else [False] * d.path.segments
        drones.append(_drone_report(d, companions[d.id], mocks[d.id], held[d.id], plain))
    ids = [d.id for d in scenario.drones]
    screen = Screen((first.home[0], first.home[1])) if len(ids) > SCREEN_FROM else None
    local = Local((first.home[0], first.home[1]))

    @functools.cache
    def changed(ident: int) -> bool:
        return deviation(mocks[ident].trajectory, baseline[ident], local) > DEVIATED_M

    pairs = [
        _pair_report(
            scenario,
            specs[a],
            specs[b],
            paths,
            capsule,
            mocks,
            baseline,
            companions,
            screen,
            local,
            changed,
        )
        for i, a in enumerate(ids)
        for b in ids[i + 1 :]
    ]
    return ReplayReport(
        scenario=scenario.name,
        link=LinkInfo(scenario.link_profile, scenario.loss, scenario.seed),
        time_scale=time_scale,
        virtual_time=virtual,
        finished=finished,
        offset_m=scenario.offset_m,
        drones=drones,
        pairs=pairs,
        conflicts=sum(p.conflict and p.trusted for p in pairs),
        conflicts_resolved=sum(p.resolved for p in pairs),
        untrusted_conflicts=sum(p.conflict and not p.trusted for p in pairs),
        precautionary_actions=sum(len(d.precautionary) for d in drones),
        false_alarms=sum(p.false_alarm for p in pairs),
        made_worse=sum(p.made_worse for p in pairs),
        separation_m=scenario.separation_m,
        vertical_separation_m=scenario.vertical_separation_m,
    ).judged()


def _drone_report(
    d: DroneSpec,
    c: Companion,
    vehicle: ReplayVehicle,
    held: list[MissionItem],
    plain: list[bool],
) -> DroneReport:
    """One drone: what its companion found, did and sent; ``plain``: its segments that the
    plaintext predicate finds in conflict with a peer's path."""
    stats = c.endpoint.stats
    run_auth = sum(
        e.payload.auth_bytes for e in c.events if isinstance(e.payload, RunResult | Answered)
    )
    position_beacons = c.sender.sent[BeaconKind.SIGNED] + c.sender.sent[BeaconKind.TAGGED]
    return DroneReport(
        id=d.id,
        operator=d.operator,
        autopilot="ardupilot" if d.ardupilot else "px4",
        vehicle=vehicle.kind,
        segments=d.path.segments,
        conflicting_segments=[k for k, h in enumerate(plain) if h],
        flagged_segments=sorted(c.edits.flagged),
        raises={str(k): v for k, v in sorted(c.flight.raises.items())},
        edits=[e.detail for e in c.events if e.kind is K.UPLOADED],
        edit=_edit_status(c),
        runs_unfinished=_unfinished(c),
        runs=[e.detail | {"t_s": round(e.t, 1)} for e in c.events if e.kind is K.RESULT],
        failures=[e.detail | {"kind": e.kind} for e in c.events if e.failed],
        precautionary=[
            {"t_s": round(e.t, 1), **e.detail} for e in c.events if e.kind is K.PRECAUTIONARY
        ],
        timeline=[
            {"t_s": round(e.t, 1), "kind": e.kind}
            | {k: v for k, v in e.detail.items() if k in ("peer", "phase", "why")}
            for e in c.events
            if e.kind in TIMELINE
        ],
        bytes_sent=stats.bytes_sent,
        frames_sent=stats.frames_sent,
        airtime_s=round(stats.airtime_s, 3),
        auth=AuthCost(
            run_bytes=run_auth,
            beacon_bytes=c.sender.bytes_sent,
            beacons={str(k): v for k, v in c.sender.sent.items()},
            beacon_added_bytes=c.sender.bytes_sent - UNAUTHENTICATED_SIZE * position_beacons,
        ),
        guard_bytes=sum(e.payload.guard_bytes for e in c.events if isinstance(e.payload, Answered)),
        untrusted_heard=[
            e.payload.drone
            for e in c.events
            if e.kind is K.UNTRUSTED and isinstance(e.payload, Stranger)
        ],
        beacons_rejected=dict(c.neighbourhood.rejected),
        max_altitude_m_amsl=round(max((alt for *_, alt in vehicle.trajectory), default=0.0), 2),
        vehicle_holds=_holds(held, d.mission, c.flight.mission, d.ardupilot),
    )


def _pair_report(
    scenario: Scenario,
    da: DroneSpec,
    db: DroneSpec,
    paths: dict[int, tuple[Point, ...]],
    capsule: Separation,
    mocks: dict[int, ReplayVehicle],
    baseline: dict[int, Track],
    companions: dict[int, Companion],
    screen: Screen | None,
    local: Local,
    changed: Callable[[int], bool],
) -> PairReport:
    """One pair: did their protected volumes meet without the companions (a conflict), and
    with them; did they act, in time, and was it enough.  With a ``screen`` (a busy sky) a
    pair that never came within FAR_M is told from its coarse closest approach."""
    a, b = da.id, db.id
    r, v = scenario.separation_m, scenario.vertical_separation_m
    flown_a, flown_b = mocks[a].trajectory, mocks[b].trajectory
    # each vehicle holds its altitude to within its own accuracy
    tolerance = mocks[a].altitude_accuracy_m + mocks[b].altitude_accuracy_m
    far = screen.closest(flown_a, flown_b) if screen else 0.0
    far_baseline = screen.closest(baseline[a], baseline[b]) if screen else 0.0
    if min(far, far_baseline) > FAR_M:  # never near: no exact comparison needed
        with_companion, when, without = far, 0.0, far_baseline
        inside_before, met, inside_after = 0.0, math.inf, 0.0
    else:
        grounds = (da.home[2], db.home[2])
        with_companion, when, _, _ = closest(flown_a, flown_b, local)
        without, _, _, _ = closest(baseline[a], baseline[b], local)
        inside_before, met = intrusion(baseline[a], baseline[b], r, v, local, grounds)
        inside_after, _ = intrusion(flown_a, flown_b, r, v - tolerance, local, grounds)
    trusted = scenario.trusted_pair(da, db)
    conflict = inside_before > 0
    # a pair with an operator outside the trust store is deliberately not deconflicted
    acted = trusted and (_acted(companions[a], b, met) or _acted(companions[b], a, met))
    ever = trusted and (
        _acted(companions[a], b, math.inf, clear_of=False)
        or _acted(companions[b], a, math.inf, clear_of=False)
    )
    return PairReport(
        drones=(a, b),
        trusted=trusted,
        paths_cross=any(path_hits(paths[a], paths[b])),
        paths_near=any(route_hits(Route(paths[a]), Route(paths[b]), capsule)),
        conflict=conflict,
        acted=acted,
        # what the companions made of a pair needs either drone to have flown differently
        resolved=conflict and acted and inside_after == 0 and (changed(a) or changed(b)),
        made_worse=with_companion < without - tolerance
        and inside_after > 0
        and (changed(a) or changed(b)),
        false_alarm=ever and not conflict,
        closest_approach_m=round(with_companion, 2),
        closest_approach_t_s=round(when, 1),
        closest_approach_baseline_m=round(without, 2),
        resolved_tolerance_m=tolerance,
        inside_s=round(inside_after, 1),
        inside_baseline_s=round(inside_before, 1),
    )


def _edit_status(c: Companion) -> EditStatus:
    """What became of the drone's mission: "verified" (an edit uploaded and read back the
    same), "failed" (an edit was needed and did not land) or "not needed"."""
    if any(e.kind in (K.PLAN_FAILED, K.UPLOAD_FAILED) for e in c.events):
        return EditStatus.FAILED
    if any(e.kind is K.UPLOADED for e in c.events):
        return EditStatus.VERIFIED
    return EditStatus.NOT_NEEDED


def _unfinished(c: Companion) -> int:
    """Runs as Alice that started and neither gave a result nor failed (cut by the end)."""
    open_runs = 0
    for e in c.events:
        if e.kind is K.RUN_STARTED:
            open_runs += 1
        elif e.kind in RUN_ENDS and open_runs:
            open_runs -= 1
    return open_runs


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
