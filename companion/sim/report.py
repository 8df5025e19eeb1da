"""The replay's report: what each drone did, each pair's separation, and the verdict.

Typed (:class:`ReplayReport`, one :class:`DroneReport` per drone, one :class:`PairReport` per
pair); :meth:`ReplayReport.to_json` is what ``replay --json`` prints, field for field.
``problems`` is everything that makes a replay a failure (exit 1), ``notes`` what the summary
states without failing it (its last line is then ``OK (with notes): ...``, never a bare
``OK``); ``ok`` only when there is no problem.  Names carry their units
(``_m``, ``_s``, ``_m_amsl``).  The measuring is :mod:`companion.sim.metrics`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from companion.events import FAILURES

VEHICLE_NAMES = {
    ("mock", "px4"): "px4",
    ("mock", "ardupilot"): "ardupilot",
    ("px4-sitl", "px4"): "PX4 SITL",
    ("in-process", "px4"): "px4, in process",
    ("in-process", "ardupilot"): "ardupilot, in process",
}

Detail = dict[str, Any]  # a companion event's detail as JSON (its kind's own fields)


class EditStatus(StrEnum):
    """What became of a drone's mission."""

    VERIFIED = "verified"  # an edit uploaded and read back the same
    FAILED = "failed"  # an edit was needed and did not land
    NOT_NEEDED = "not needed"


@dataclass(frozen=True)
class AuthCost:
    """What authentication cost a drone on the radio (:mod:`companion.auth`)."""

    run_bytes: int  # key exchange and tags of finished runs
    beacon_bytes: int  # beacon payloads sent, all kinds
    beacons: dict[str, int]  # beacons sent by kind: signed, tagged, certificate
    beacon_added_bytes: int  # beyond unauthenticated 24-byte position beacons


@dataclass(frozen=True)
class DroneReport:
    id: int
    operator: str
    autopilot: str  # "px4" or "ardupilot"
    vehicle: str  # "mock" or "px4-sitl"
    segments: int
    conflicting_segments: list[int]  # the plain predicate against every trusted peer
    flagged_segments: list[int]  # what the runs flagged, at a verified edit of the flight
    raises: dict[str, float]  # segment -> metres higher, as uploaded
    edits: list[Detail]
    edit: EditStatus
    runs_unfinished: int  # runs as Alice cut off by the end
    runs: list[Detail]
    failures: list[Detail]  # each with its "kind"
    precautionary: list[Detail]
    timeline: list[Detail]
    bytes_sent: int
    frames_sent: int
    airtime_s: float
    auth: AuthCost
    untrusted_heard: list[str]
    beacons_rejected: dict[str, int]
    max_altitude_m_amsl: float
    vehicle_holds: str  # "original", "edited" or "other"
    guard_bytes: int = 0  # of its answers' bytes: checks against a deviating peer


@dataclass(frozen=True)
class PairReport:
    drones: tuple[int, int]
    trusted: bool
    paths_cross: bool  # the ground tracks cross (the paper's predicate)
    paths_near: bool  # the ground tracks come within the horizontal separation
    conflict: bool  # without the companion they came inside each other's protected volume
    acted: bool  # a precaution or a verified edit for the pair (before the first intrusion)
    resolved: bool  # a conflict, acted upon, and never inside with the companion
    made_worse: bool  # the companion brought them closer, and inside the protected volume
    false_alarm: bool  # an edit or precaution for the pair, which never came inside without
    closest_approach_m: float
    closest_approach_t_s: float
    closest_approach_baseline_m: float
    resolved_tolerance_m: float
    inside_s: float = 0.0  # seconds inside the protected volume with the companion
    inside_baseline_s: float = 0.0  # and without


@dataclass(frozen=True)
class LinkInfo:
    profile: str
    loss: float
    seed: int | None  # None: a fresh seed each run


@dataclass(frozen=True)
class ReplayReport:
    scenario: str
    link: LinkInfo
    time_scale: float
    finished: bool  # every mission flown before the time limit
    offset_m: float
    drones: list[DroneReport]
    pairs: list[PairReport]
    conflicts: int
    conflicts_resolved: int
    untrusted_conflicts: int  # with drones outside the trust stores: not handled
    precautionary_actions: int
    false_alarms: int  # pairs with an edit or a precaution that never came inside without
    made_worse: int = 0  # pairs the companion brought closer, inside the protected volume
    virtual_time: bool = False  # flown in virtual time, vehicles in process (no MAVSDK)
    separation_m: float = 15.0  # the protected volume: horizontally
    vertical_separation_m: float = 10.0  # and vertically
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def judged(self) -> ReplayReport:
        """This report with its problems and notes."""
        return dataclasses.replace(self, problems=problems(self), notes=notes(self))

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self) | {"ok": self.ok}

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> ReplayReport:
        """A report from its JSON (``--out``); ``ok`` is derived, not read."""
        drones = [
            DroneReport(**(d | {"edit": EditStatus(d["edit"]), "auth": AuthCost(**d["auth"])}))
            for d in doc["drones"]
        ]
        pairs = [PairReport(**(p | {"drones": tuple(p["drones"])})) for p in doc["pairs"]]
        nested = {"link", "drones", "pairs", "ok"}
        rest = {k: v for k, v in doc.items() if k not in nested}
        return cls(**rest, link=LinkInfo(**doc["link"]), drones=drones, pairs=pairs)


def notes(report: ReplayReport) -> list[str]:
    """What the summary states without failing the replay: precautionary actions, runs that
    failed (and were retried), runs the end of the replay cut off (every mission flown)."""
    out = []
    for d in report.drones:
        if d.precautionary:
            out.append(f"drone {d.id}: {len(d.precautionary)} precautionary action(s)")
        failed = [f for f in d.failures if f["kind"] not in FAILURES]
        if failed:
            kinds = ", ".join(sorted({f["kind"].replace("_", " ") for f in failed}))
            out.append(f"drone {d.id}: {len(failed)} run(s) ended without a result ({kinds})")
        if d.runs_unfinished:
            out.append(f"drone {d.id}: {d.runs_unfinished} run(s) still under way at the end")
    return out


def problems(report: ReplayReport) -> list[str]:
    """Everything that makes a replay a failure, one line each (empty: it succeeded)."""
    out = []
    if not report.finished:
        out.append("the time limit ended the replay before every mission was flown")
    for d in report.drones:
        for failure in d.failures:
            if failure["kind"] in FAILURES:
                why = failure.get("error") or failure.get("why") or ""
                out.append(f"drone {d.id}: {failure['kind'].replace('_', ' ')}: {why}")
    volume = f"{report.separation_m:g} m / {report.vertical_separation_m:g} m"
    for p in report.pairs:
        a, b = p.drones
        if p.conflict and p.trusted and not p.resolved:
            out.append(
                f"drones {a}-{b}: conflict NOT resolved ({p.inside_s:.0f} s inside the "
                f"protected volume, {volume}; closest approach {p.closest_approach_m:.1f} m)"
            )
        if p.made_worse:
            out.append(
                f"drones {a}-{b}: made WORSE by the companion (closest approach "
                f"{p.closest_approach_baseline_m:.1f} m without it, {p.closest_approach_m:.1f} m "
                f"with it, inside the protected volume {volume})"
            )
        if p.false_alarm:
            out.append(
                f"drones {a}-{b}: false alarm (an edit or precaution, but never inside the "
                f"protected volume {volume} without the companion)"
            )
    return out


def _drone_line(d: DroneReport, offset_m: float) -> str:
    if d.edit is EditStatus.VERIFIED:
        raises = ", ".join(f"{k} ({v:+.0f} m)" for k, v in d.raises.items())
        what = f"flies segments {raises or 'none'} higher (upload verified)"
    elif d.edit is EditStatus.FAILED:
        what = "needed an edit that FAILED, flies its original altitudes"
    else:
        what = "kept its altitude (no edit needed)"
    if d.precautionary:
        what += f"; {len(d.precautionary)} precautionary action(s)"
    if d.failures:
        kinds = sorted({f["kind"] for f in d.failures})
        what += f"; {len(d.failures)} failure(s): {', '.join(kinds)}"
    if d.runs_unfinished:
        what += f"; {d.runs_unfinished} run(s) never finished"
    if d.untrusted_heard:
        what += f"; ignored {len(d.untrusted_heard)} untrusted drone(s)"
    return (
        f"  drone {d.id} ({VEHICLE_NAMES[d.vehicle, d.autopilot]}, "
        f"{d.operator}): {what}; radio {d.bytes_sent} B in {d.frames_sent} frames, "
        f"{d.airtime_s:.1f} s airtime (authentication adds {d.auth.run_bytes} B to "
        f"runs, {d.auth.beacon_added_bytes} B to beacons; the checks against a deviating "
        f"peer {d.guard_bytes} B)"
    )


def _pair_line(p: PairReport) -> str:
    a, b = p.drones
    if not p.trusted:
        return (
            f"  drones {a}-{b}: not deconflicted (an operator outside the trust store); "
            f"closest approach {p.closest_approach_m:.1f} m"
        )
    verdict = "resolved" if p.resolved else "NOT resolved" if p.conflict else "no conflict"
    if p.made_worse:
        verdict += ", made WORSE"
    if p.false_alarm:
        verdict += ", a false alarm"
    return (
        f"  drones {a}-{b}: closest approach {p.closest_approach_baseline_m:.1f} m "
        f"without the companion, {p.closest_approach_m:.1f} m with it "
        f"(t = {p.closest_approach_t_s:.0f} s): {verdict}"
    )


NEAR_FACTOR = 5.0  # a pair "came near" within this many horizontal separations
FEW = 3  # up to this many drones (or pairs) everything is listed


def came_near(report: ReplayReport, pair: PairReport) -> bool:
    """A pair worth showing among many: the companion acted for it, or it had (or should
    have had) a conflict, or it came within ``NEAR_FACTOR`` separations with or without
    the companion."""
    near = NEAR_FACTOR * report.separation_m
    closest = min(pair.closest_approach_m, pair.closest_approach_baseline_m)
    return pair.conflict or pair.acted or pair.false_alarm or pair.made_worse or closest <= near


def shown_pairs(report: ReplayReport) -> list[PairReport]:
    """Every pair of a small replay; of a busy sky only those that came near."""
    if len(report.pairs) <= FEW:
        return list(report.pairs)
    return [p for p in report.pairs if came_near(report, p)]


def levels_up(d: DroneReport, offset_m: float) -> int:
    """How many offsets above its plan the drone flew at most: its largest raise in any
    verified edit (a precaution's climb, undone later, counts)."""
    raised = [abs(float(v)) for e in d.edits for v in e.get("raises", {}).values()]
    top = max([*raised, *(abs(v) for v in d.raises.values())], default=0.0)
    return math.ceil(top / offset_m - 1e-9) if offset_m > 0 else 0


def drone_table(report: ReplayReport) -> list[str]:
    """One line per drone: what it flew, what it sent and what went wrong, in columns."""
    head = (
        f"  {'drone':>5}  {'levels up':>9}  {'edit':<10}  {'precautions':>11}  "
        f"{'results':>7}  {'failed':>6}  {'unfinished':>10}  {'bytes':>8}  {'airtime s':>9}"
    )
    lines = [head]
    for d in report.drones:
        failed = sum(1 for f in d.failures if f["kind"] not in FAILURES)
        broke = len(d.failures) - failed
        edit = d.edit.value + (f" ({broke} failure(s))" if broke else "")
        lines.append(
            f"  {d.id:>5}  {levels_up(d, report.offset_m):>9}  {edit:<10}  "
            f"{len(d.precautionary):>11}  {len(d.runs):>7}  {failed:>6}  "
            f"{d.runs_unfinished:>10}  {d.bytes_sent:>8}  {d.airtime_s:>9.1f}"
        )
    return lines


def format_report(report: ReplayReport) -> str:
    """The replay as text: what each drone did, each pair's separation, and every problem."""
    lines = [
        f"Replay {report.scenario} over {report.link.profile} "
        f"(loss {report.link.loss:.0%}), "
        + ("in virtual time" if report.virtual_time else f"time scale {report.time_scale}x")
        + ("" if report.finished else " -- TIME LIMIT REACHED before every mission was flown")
        + ":"
    ]
    if len(report.drones) <= FEW:
        lines += [_drone_line(d, report.offset_m) for d in report.drones]
    else:
        lines += drone_table(report)
    shown = shown_pairs(report)
    lines += [_pair_line(p) for p in shown]
    if len(shown) < len(report.pairs):
        lines.append(
            f"  {len(report.pairs) - len(shown)} other pair(s) never came within "
            f"{NEAR_FACTOR * report.separation_m:.0f} m of each other, with or without the "
            "companion, and nothing was done for them"
        )
    lines.append(
        f"  conflicts resolved {report.conflicts_resolved}/{report.conflicts}, "
        f"precautionary actions {report.precautionary_actions}, "
        f"false alarms {report.false_alarms}, made worse {report.made_worse}"
        + (
            f"; {report.untrusted_conflicts} conflict(s) with untrusted drones NOT handled"
            if report.untrusted_conflicts
            else ""
        )
    )
    if report.notes:
        lines.append("Notes:")
        lines.extend(f"  - {line}" for line in report.notes)
    if report.problems:
        lines.append(f"FAILED ({len(report.problems)} problem(s)):")
        lines.extend(f"  - {line}" for line in report.problems)
    else:
        lines.append(_verdict(report))
    return "\n".join(lines)


def _verdict(report: ReplayReport) -> str:
    """The last line of a replay without problems: a bare ``OK`` only when nothing is noted,
    so a reader never sees it under failed runs or precautions (which do not fail a replay:
    retries on a lossy link are normal)."""
    precautions = sum(len(d.precautionary) for d in report.drones)
    how = "" if precautions else " by a verified action"
    verdict = f"every mission flown, every conflict resolved{how}"
    if not report.notes:
        return f"OK: {verdict}"
    failed = sum(1 for d in report.drones for f in d.failures if f["kind"] not in FAILURES)
    unfinished = sum(d.runs_unfinished for d in report.drones)
    counts = [
        (failed, "run(s) failed and were retried"),
        (precautions, "precautionary action(s) taken"),
        (unfinished, "run(s) never finished"),
    ]
    said = ", ".join(f"{n} {what}" for n, what in counts if n)
    return f"OK (with notes): {verdict}; but {said or 'see the notes'} (Notes above)"
