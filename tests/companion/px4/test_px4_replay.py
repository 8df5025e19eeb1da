"""Two-drone replays with both vehicles on real PX4 v1.16 SITL (SIH): the companions talk to
PX4 through MAVSDK on its onboard link, as on a real drone; the harness starts the missions
and records the tracks over the GCS link.  About a minute each at speed factor 10."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from companion.sim.px4 import Px4Build
from companion.sim.replay import run_replay
from companion.sim.scenario import load_scenario

pytestmark = [pytest.mark.px4, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

SCENARIOS = Path(__file__).resolve().parents[3] / "sitl_configs" / "scenarios"


def test_crossing_on_two_px4_vehicles(px4_build: Px4Build) -> None:
    """Drone 1 (on the ground) compares with drone 2 (holding over the mast), climbs over
    the crossing leg on PX4 (the upload verified by meaning: PX4 reads frame 3 back as 6),
    and the two PX4 vehicles pass with the offset between them."""
    scenario = load_scenario(SCENARIOS / "crossing.toml")
    # at SIH's 10x: nothing on this scenario is close to a deadline (the default cap of 5 is
    # for in-flight encounters, where the companions' CPU time counts in simulated time)
    report = asyncio.run(run_replay(scenario, px4=px4_build, px4_speed_max=10.0)).report.to_json()
    assert report["finished"], report
    assert report["time_scale"] == 10.0  # the scenario's 40x capped at SIH's 10x
    first, second = report["drones"]
    assert first["vehicle"] == second["vehicle"] == "px4-sitl"
    assert first["flagged_segments"] == first["conflicting_segments"] == [0]  # the crossing
    assert first["edit"] == "verified" and first["vehicle_holds"] == "edited"
    assert not second["edits"] and second["vehicle_holds"] == "original"
    (pair,) = report["pairs"]
    assert pair["conflict"] and pair["closest_approach_baseline_m"] < 2.0
    assert pair["resolved"] and pair["resolved_tolerance_m"] == 1.5
    assert pair["closest_approach_m"] >= report["offset_m"] - pair["resolved_tolerance_m"]
    assert report["conflicts_resolved"] == report["conflicts"] == 1
    assert report["false_alarms"] == 0


def test_first_leg_crossing_on_two_px4_vehicles(px4_build: Px4Build) -> None:
    """Drone 2 hovers over a mast in the middle of drone 1's first leg; drone 1 learns it in
    flight, on that leg.  PX4 flies a leg as a straight 3-D line, so raising only the leg's
    far end would pass the mast half way up the ramp: the companion inserts a waypoint at
    the raised altitude ahead of the vehicle (marked current, PX4 flies on from it) and the
    two PX4 vehicles pass at least the offset apart, less PX4's altitude error."""
    scenario = load_scenario(SCENARIOS / "sep_first_leg.toml")
    report = asyncio.run(run_replay(scenario, px4=px4_build)).report.to_json()
    assert report["finished"], report
    first, second = report["drones"]
    assert first["vehicle"] == second["vehicle"] == "px4-sitl"
    assert first["edit"] == "verified" and first["vehicle_holds"] == "edited"
    assert any(edit["inserted"] is not None for edit in first["edits"])  # the leg was split
    assert not second["edits"]
    (pair,) = report["pairs"]
    assert pair["conflict"] and pair["resolved"] and pair["inside_s"] == 0
    assert pair["closest_approach_m"] >= report["offset_m"] - pair["resolved_tolerance_m"]
    assert report["false_alarms"] == report["made_worse"] == 0
