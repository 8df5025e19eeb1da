"""What a replay measured: each drone's runs, edits and radio costs from its companion's
events, each pair's closest approach with the companions and without them (the baseline),
and whether a conflict was resolved by the companions' action -- made into the typed
:class:`~companion.sim.report.ReplayReport`.
"""

from __future__ import annotations

import math

from protocol.geodesy import ground_offset
from protocol.geometry import path_hits
from protocol.grid import GridSpec

from ..autopilots import personality
from ..beacon import UNAUTHENTICATED_SIZE
from ..events import RUN_ENDS
from ..events import EventKind as K
from ..mission import MissionItem, point_as_segment
from ..runtime import Companion
from .report import AuthCost, DroneReport, EditStatus, LinkInfo, PairReport, ReplayReport
from .scenario import Scenario
from .vehicles import ReplayVehicle, Track

REPORT_RADIUS_M = 50_000.0  # the report's own grid (plain predicate only): any encounter fits


def enu(a: tuple[float, float, float], ref: tuple[float, float]) -> tuple[float, float, float]:
    """(north, east, up) metres of ``a`` (lat, lon, alt) from ``ref`` (lat, lon)."""
    return (*ground_offset(ref[0], ref[1], a[0], a[1]), a[2])


TIMELINE = frozenset(
    {
        K.RUN_STARTED,
        K.RESULT,
        K.RUN_FAILED,
        K.UPLOADED,
        K.PRECAUTIONARY,
        K.HOLD,
        K.RESUMED,
        K.SETUP_RENEWED,
    }
)


def closest(
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
        d = math.dist(enu((lat, lon, alt), (a[0][1], a[0][2])), enu(b[j][1:], (a[0][1], a[0][2])))
        if d < best[0]:
            best = (d, t, (lat, lon, alt), b[j][1:])
    return best


def _acted(c: Companion, peer: int, until: float) -> bool:
    """Did this companion act on its pair with ``peer`` before ``until``: a precautionary
    action for it, or a verified edit that flies a segment a result flagged for it higher?"""
    if any(
        e.kind is K.PRECAUTIONARY and e.detail.get("peer") == peer and e.t <= until
        for e in c.events
    ):
        return True
    flagged = {
        k
        for e in c.events
        if e.kind is K.RESULT and e.detail.get("peer") == peer and e.t <= until
        for k in e.detail.get("flagged", [])
    }
    return any(
        e.kind is K.UPLOADED
        and e.t <= until
        and e.detail.get("verified")
        and flagged & {int(k) for k in e.detail.get("levels", {})}
        for e in c.events
    )


def build_report(
    scenario: Scenario,
    mocks: dict[int, ReplayVehicle],
    held: dict[int, list[MissionItem]],
    companions: dict[int, Companion],
    baseline: dict[int, Track],
    finished: bool,
    time_scale: float,
) -> ReplayReport:
    """The report of a replay (judged: problems and notes filled in)."""
    first = scenario.drones[0]
    grid = GridSpec.geo(
        round(first.home[0] * 1e7), round(first.home[1] * 1e7), radius_m=REPORT_RADIUS_M
    )
    paths = {  # a hover is a point, as Bob sends it
        d.id: point_as_segment(grid.project_path(d.path.points, checked=False))
        for d in scenario.drones
    }
    drones: list[DroneReport] = []
    false_alarms, precautions = 0, 0
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
            {"t_s": round(e.t, 1), **e.detail} for e in c.events if e.kind is K.PRECAUTIONARY
        ]
        precautions += len(precautionary)
        stats = c.endpoint.stats
        run_auth = sum(
            e.detail.get("auth_bytes", 0) for e in c.events if e.kind in (K.RESULT, K.ANSWERED)
        )
        position_beacons = c.beacons_sent["signed"] + c.beacons_sent["tagged"]
        drones.append(
            DroneReport(
                id=d.id,
                operator=d.operator,
                autopilot="ardupilot" if d.ardupilot else "px4",
                vehicle=mocks[d.id].kind,
                segments=d.path.segments,
                conflicting_segments=[k for k, h in enumerate(plain) if h],
                flagged_segments=flagged,
                levels={str(k): v for k, v in sorted(c.levels.items())},
                edits=[e.detail for e in c.events if e.kind is K.UPLOADED],
                edit=_edit_status(c),
                runs_unfinished=_unfinished(c),
                runs=[e.detail | {"t_s": round(e.t, 1)} for e in c.events if e.kind is K.RESULT],
                failures=[e.detail | {"kind": e.kind} for e in c.events if e.failed],
                precautionary=precautionary,
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
                    beacon_bytes=c.beacon_bytes,
                    beacons=dict(c.beacons_sent),
                    beacon_added_bytes=c.beacon_bytes - UNAUTHENTICATED_SIZE * position_beacons,
                ),
                guard_bytes=sum(
                    e.detail.get("guard_bytes", 0) for e in c.events if e.kind is K.ANSWERED
                ),
                untrusted_heard=[e.detail["drone"] for e in c.events if e.kind is K.UNTRUSTED],
                beacons_rejected=dict(c.rejected),
                max_altitude_m_amsl=round(
                    max((alt for *_, alt in mocks[d.id].trajectory), default=0.0), 2
                ),
                vehicle_holds=_holds(held[d.id], d.mission, c.mission, d.ardupilot),
            )
        )
    pairs: list[PairReport] = []
    resolved, conflicts, untrusted = 0, 0, 0
    ids = [d.id for d in scenario.drones]
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            crossing = any(path_hits(paths[a], paths[b]))
            with_companion, when, _, _ = closest(mocks[a].trajectory, mocks[b].trajectory)
            without, _, _, _ = closest(baseline[a], baseline[b])
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
                PairReport(
                    drones=(a, b),
                    trusted=trusted,
                    paths_cross=crossing,
                    conflict=conflict,
                    acted=acted,
                    resolved=ok,
                    closest_approach_m=round(with_companion, 2),
                    closest_approach_t_s=round(when, 1),
                    closest_approach_baseline_m=round(without, 2),
                    resolved_tolerance_m=tolerance,
                )
            )
    return ReplayReport(
        scenario=scenario.name,
        link=LinkInfo(scenario.link_profile, scenario.loss, scenario.seed),
        time_scale=time_scale,
        finished=finished,
        offset_m=scenario.offset_m,
        drones=drones,
        pairs=pairs,
        conflicts=conflicts,
        conflicts_resolved=resolved,
        untrusted_conflicts=untrusted,
        precautionary_actions=precautions,
        false_alarms=false_alarms,
    ).judged()


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
