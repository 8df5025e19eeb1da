"""The shipped scenarios end to end: mock autopilots, real MAVSDK over UDP, companions on one
simulated radio, flown in scaled time.  Slow (tens of seconds each), part of ``make test``."""

from __future__ import annotations

import asyncio
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.mock_autopilot import Faults
from companion.replay import (
    KINEMATIC_TOLERANCE_M,
    Scenario,
    ScenarioError,
    load_scenario,
    run_replay,
)

SCENARIOS = Path(__file__).resolve().parents[2] / "sitl_configs" / "scenarios"


def _replay(name: str) -> dict:  # type: ignore[type-arg]
    run = subprocess.run(
        [sys.executable, "-m", "companion", "replay", str(SCENARIOS / f"{name}.toml"), "--json"],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert run.returncode in (0, 1), run.stderr[-3000:]
    return json.loads(run.stdout)  # type: ignore[no-any-return]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "climbers"),
    [
        ("crossing", {1}),
        ("corridor", {1}),
        ("no_conflict", set()),
        ("three_drones", {1}),
        ("ardupilot", {1}),
        ("lossy_sf9", {1}),
    ],
)
def test_scenario(name: str, climbers: set[int]) -> None:
    report = _replay(name)
    assert report["finished"], "the missions were not flown within the time limit"
    offset = report["offset_m"]
    for drone in report["drones"]:
        flagged, conflicting = set(drone["flagged_segments"]), set(drone["conflicting_segments"])
        assert flagged <= conflicting  # nothing flagged that the plain predicate clears
        if drone["id"] in climbers:
            assert flagged == conflicting  # every true 2-D conflict of Alice's mission
            assert drone["verified"] and drone["edits"]
            assert drone["max_altitude_m"] >= 488.0 + 30.0 + offset - 0.5
        else:
            assert not drone["edits"]
    assert report["false_alarms"] == 0
    for pair in report["pairs"]:
        if pair["paths_cross"]:
            # without the companion they would have met; with it, the offset separates them
            assert pair["closest_approach_baseline_m"] < offset - KINEMATIC_TOLERANCE_M
            assert pair["closest_approach_m"] >= offset - KINEMATIC_TOLERANCE_M
    assert report["conflicts_resolved"] == report["conflicts"]
    if not climbers:
        assert report["conflicts"] == 0
    if name == "three_drones":
        assert report["conflicts"] == 2
    if name == "lossy_sf9":
        assert report["link"]["profile"] == "eu868-sf9" and report["link"]["loss"] == 0.3


def test_bad_scenarios_are_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    for text, message in [
        ("time_scale = 'fast'\n[[drone]]\nid=1\nmission='a.plan'\n", "time_scale"),
        ("[link]\nprofile = 'eu433'\n", "unknown link profile"),
        ("[[drone]]\nid = 1\nmission = 'a.plan'\n", "at least two"),
        (
            "[[drone]]\nid = 1\nmission = 'missing.plan'\n[[drone]]\nid = 2\nmission = 'x'\n",
            "drone 1",
        ),
        ("not toml [", "bad.toml"),
    ]:
        bad.write_text(text)
        with pytest.raises(ScenarioError, match=message):
            load_scenario(bad)


def _crossing(**changes: object) -> Scenario:
    scenario = load_scenario(SCENARIOS / "crossing.toml")
    changes.setdefault("time_scale", 80.0)
    return dataclasses.replace(scenario, **changes)  # type: ignore[arg-type]


def _drone(scenario: Scenario, ident: int, **changes: object) -> Scenario:
    drones = [
        dataclasses.replace(d, **changes) if d.id == ident else d  # type: ignore[arg-type]
        for d in scenario.drones
    ]
    return dataclasses.replace(scenario, drones=drones)


@pytest.mark.slow
def test_fault_rejected_upload_keeps_the_old_mission() -> None:
    scenario = _drone(_crossing(), 1, faults=Faults(reject_upload=mavlink.MAV_MISSION_NO_SPACE))
    report = asyncio.run(run_replay(scenario)).report
    alice = report["drones"][0]
    assert alice["runs"] and alice["flagged_segments"] == []  # planned, but never applied
    assert any(f["kind"] == "upload_failed" for f in alice["failures"])
    assert alice["vehicle_holds"] == "original" and report["finished"]
    assert report["conflicts_resolved"] == 0  # honest: the vehicle could not be told


@pytest.mark.slow
def test_fault_peer_vanishes_mid_run() -> None:
    scenario = _drone(_crossing(), 2, companion_stop_s=150.0)
    report = asyncio.run(run_replay(scenario)).report
    alice = report["drones"][0]
    assert any(f["kind"] == "run_failed" for f in alice["failures"])
    assert not alice["edits"] and alice["vehicle_holds"] == "original"
    assert report["finished"]  # the companion kept going and the missions were flown


@pytest.mark.slow
def test_fault_link_at_30_percent_loss() -> None:
    """At 30 % loss the comparison takes about twice as long: drone 1 waits longer on the
    ground and drone 2 holds longer over the mast."""
    scenario = _crossing(loss=0.3, seed=9, time_scale=100.0, time_limit_s=2600.0)
    inspection = scenario.drones[1]
    longer = [it.replace(param1=1800.0) if it.command == 19 else it for it in inspection.mission]
    scenario = _drone(_drone(scenario, 2, mission=longer), 1, takeoff_delay_s=1300.0)
    report = asyncio.run(run_replay(scenario)).report
    alice = report["drones"][0]
    assert alice["flagged_segments"] == alice["conflicting_segments"] == [0]
    assert alice["vehicle_holds"] == "edited"
    assert report["conflicts_resolved"] == report["conflicts"] == 1
