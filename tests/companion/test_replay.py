"""The shipped scenarios end to end: mock autopilots, real MAVSDK over UDP, companions on one
simulated radio, flown in scaled time.  Slow (tens of seconds each), part of ``make test``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from companion.replay import KINEMATIC_TOLERANCE_M, ScenarioError, load_scenario

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
    assert (
        report["conflicts_resolved"]
        == report["conflicts"]
        == (0 if not climbers else report["conflicts"])
    )
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
