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
