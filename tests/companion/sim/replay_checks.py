"""What every replay test asks of a report (over MAVSDK or in virtual time), and the
scenarios they fly."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from companion.sim.scenario import Scenario, load_scenario
from companion.sim.vehicles import RESOLVED_TOLERANCE_M

SCENARIOS = Path(__file__).resolve().parents[3] / "sitl_configs" / "scenarios"
Report = dict[str, Any]


def check(report: Report, climbers: set[int], *, precautions: int = 0) -> None:
    """Every conflict resolved by the companion, none by luck, none made worse, no false
    alarm, at most ``precautions`` precautionary actions (those for a pair in conflict);
    exactly the drones in ``climbers`` end flying higher -- by at least the offset, over
    segments the runs flagged, which come within the separation of another drone's path
    (what the runs compare is the protected volume: a segment near in space but not in time
    or altitude is no conflict)."""
    assert report["finished"], "the missions were not flown within the time limit"
    offset = report["offset_m"]
    for drone in report["drones"]:
        flagged, near = set(drone["flagged_segments"]), set(drone["conflicting_segments"])
        assert flagged <= near  # nothing flagged that is not even near in space
        if drone["id"] in climbers:
            assert flagged and drone["edit"] == "verified" and drone["edits"]
            assert all(v >= offset for v in drone["raises"].values()), drone["raises"]
            assert drone["max_altitude_m_amsl"] >= 488.0 + 30.0 + offset - 0.5
        else:  # (an edit undone -- a peer that climbed away for a third drone -- ends level)
            assert not drone["raises"] and drone["edit"] != "failed"
        for event in drone["timeline"]:
            assert event["t_s"] >= 0
    # (a precaution allowed for a pair that turns out clear is that pair's false alarm)
    allowed = report["precautionary_actions"] if precautions else 0
    assert report["false_alarms"] <= allowed and report["made_worse"] == 0
    assert report["precautionary_actions"] <= precautions, [
        (d["id"], d["precautionary"], d["runs"]) for d in report["drones"] if d["precautionary"]
    ]
    for pair in report["pairs"]:
        if pair["conflict"]:
            # without the companion they came inside each other's protected volume; with
            # it never, and at least the offset apart
            assert pair["inside_baseline_s"] > 0 and pair["inside_s"] == 0
            assert pair["closest_approach_m"] >= offset - RESOLVED_TOLERANCE_M
            assert pair["resolved"] and pair["acted"]
    assert report["conflicts_resolved"] == report["conflicts"]
    if not precautions:
        assert report["ok"] and not report["problems"], report["problems"]


def check_in_flight(report: Report, climbing: int, conflicts: int, *, precautions: int = 0) -> None:
    """Both (all) drones airborne from the start; the result must arrive in time.  Who is
    Alice to whom depends on take-off timing, so the test asks how many climb: one drone
    per pair stays, the others fly apart in altitude -- of three, one may need no climb of
    its own once another climbed clear of it for the third."""
    climbers = {d["id"] for d in report["drones"] if d["raises"]}
    assert 1 <= len(climbers) <= climbing
    check(report, climbers, precautions=precautions)
    assert report["conflicts"] == conflicts
    for drone in report["drones"]:
        kinds = [e["kind"] for e in drone["timeline"]]
        if drone["id"] in climbers:  # when the run started, the result came, the edit landed
            assert {"run_started", "result", "uploaded"} <= set(kinds)


def check_separation(
    report: Report, name: str, climbers: set[int], conflicts: int, *, precautions: int = 0
) -> None:
    """Separation in space and time decides (scripts/make_separation_scenarios.py): near
    misses whose tracks never cross are conflicts and resolved at least the offset apart;
    a drone 5 m higher is climbed over clear of its altitude, never into it; a crossing 60 m
    apart in altitude, or minutes apart in time, is none -- no edit, no precaution; a first
    leg is flown at the offset from its start; a drone held up compares again."""
    check(report, climbers, precautions=precautions)
    assert report["conflicts"] == conflicts
    drones = {d["id"]: d for d in report["drones"]}
    if not conflicts:  # the runs found nothing: nobody flew differently
        assert all(not d["flagged_segments"] for d in drones.values())
        assert sum(bool(d["raises"]) for d in drones.values()) <= precautions
        assert all(p["closest_approach_m"] >= 15.0 for p in report["pairs"])
    if name in ("sep_parallel", "sep_tee", "sep_graze"):
        assert not report["pairs"][0]["paths_cross"]  # a near miss, not a crossing
    if name in ("sep_higher60", "sep_later"):
        assert report["pairs"][0]["paths_cross"]  # a crossing that is no conflict
    if name == "sep_higher5":  # above the peer's 35 m by the vertical separation
        assert drones[1]["max_altitude_m_amsl"] >= 488.0 + 35.0 + 10.0 - 0.5
    if name == "sep_first_leg":  # found in flight on the first leg: a waypoint inserted
        assert drones[1]["edits"][0]["inserted"] is not None
    if name == "sep_delayed":  # the hold opened its windows: compared again, then resolved
        kinds = [e["kind"] for e in drones[1]["timeline"]]
        assert "retimed" in kinds and kinds.index("retimed") < kinds.index("uploaded")


def scenario(name: str, **changes: object) -> Scenario:
    return dataclasses.replace(load_scenario(SCENARIOS / f"{name}.toml"), **changes)  # type: ignore[arg-type]


def with_drone(scenario: Scenario, ident: int, **changes: object) -> Scenario:
    drones = [
        dataclasses.replace(d, **changes) if d.id == ident else d  # type: ignore[arg-type]
        for d in scenario.drones
    ]
    return dataclasses.replace(scenario, drones=drones)
