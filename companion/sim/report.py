"""The replay's report: what each drone did, each pair's separation, and the verdict.

``problems`` is everything that makes a replay a failure (exit 1), ``notes`` what the summary
states without failing it; ``ok`` only when there is no problem.  Keys carry their units
(``_m``, ``_s``, ``_m_amsl``).
"""

from __future__ import annotations

import math
from typing import Any

from protocol.geodesy import ground_offset
from protocol.geometry import path_hits
from protocol.grid import GridSpec

from ..autopilots import personality
from ..beacon import UNAUTHENTICATED_SIZE
from ..events import FAILURES, RUN_ENDS
from ..events import EventKind as K
from ..mission import MissionItem, point_as_segment
from ..runtime import Companion
from .scenario import Scenario
from .vehicles import ReplayVehicle

VEHICLE_NAMES = {
    ("mock", "px4"): "px4",
    ("mock", "ardupilot"): "ardupilot",
    ("px4-sitl", "px4"): "PX4 SITL",
}
REPORT_RADIUS_M = 50_000.0  # the report's own grid (plain predicate only): any encounter fits
Track = list[tuple[float, float, float, float]]  # (t_s, lat, lon, alt AMSL)


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
            {"t_s": round(e.t, 1), **e.detail} for e in c.events if e.kind is K.PRECAUTIONARY
        ]
        precautions += len(precautionary)
        stats = c.endpoint.stats
        run_auth = sum(
            e.detail.get("auth_bytes", 0) for e in c.events if e.kind in (K.RESULT, K.ANSWERED)
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
                "edits": [e.detail for e in c.events if e.kind is K.UPLOADED],
                "edit": _edit_status(c),
                "runs_unfinished": _unfinished(c),
                "runs": [e.detail | {"t_s": round(e.t, 1)} for e in c.events if e.kind is K.RESULT],
                "failures": [e.detail | {"kind": e.kind} for e in c.events if e.failed],
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
                "untrusted_heard": [e.detail["drone"] for e in c.events if e.kind is K.UNTRUSTED],
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


def _edit_status(c: Companion) -> str:
    """What became of the drone's mission: "verified" (an edit uploaded and read back the
    same), "failed" (an edit was needed and did not land) or "not needed"."""
    if any(e.kind in (K.PLAN_FAILED, K.UPLOAD_FAILED) for e in c.events):
        return "failed"
    return "verified" if any(e.kind is K.UPLOADED for e in c.events) else "not needed"


def _unfinished(c: Companion) -> int:
    """Runs as Alice that started and neither gave a result nor failed (cut by the end)."""
    open_runs = 0
    for e in c.events:
        if e.kind is K.RUN_STARTED:
            open_runs += 1
        elif e.kind in RUN_ENDS and open_runs:
            open_runs -= 1
    return open_runs


def notes(report: dict[str, Any]) -> list[str]:
    """What the summary states without failing the replay: precautionary actions, runs that
    failed (and were retried), runs the end of the replay cut off (every mission flown)."""
    out = []
    for d in report["drones"]:
        if d["precautionary"]:
            out.append(f"drone {d['id']}: {len(d['precautionary'])} precautionary action(s)")
        failed = [f for f in d["failures"] if f["kind"] not in FAILURES]
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
            if failure["kind"] in FAILURES:
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
