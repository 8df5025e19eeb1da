"""The shipped scenarios end to end: mock autopilots, real MAVSDK over UDP, companions on one
simulated radio, flown in scaled time.  Slow (tens of seconds each), part of ``make test``."""

from __future__ import annotations

import asyncio
import dataclasses
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.failsafe import Action
from companion.sim.mock_autopilot import Faults
from companion.sim.replay import run_replay
from companion.sim.scenario import Scenario, ScenarioError, load_scenario
from companion.sim.vehicles import RESOLVED_TOLERANCE_M

SCENARIOS = Path(__file__).resolve().parents[3] / "sitl_configs" / "scenarios"
# real time, scaled: one replay at a time under ``make test``'s two workers
pytestmark = pytest.mark.xdist_group("realtime")


def _replay(name: str) -> dict:  # type: ignore[type-arg]
    run = subprocess.run(
        [sys.executable, "-m", "companion", "replay", str(SCENARIOS / f"{name}.toml"), "--json"],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert run.returncode in (0, 1), run.stderr[-3000:]
    report = json.loads(run.stdout)
    assert run.returncode == (0 if report["ok"] else 1)  # exit 0 only for a clean replay
    return report  # type: ignore[no-any-return]


def check(report: dict, climbers: set[int]) -> None:  # type: ignore[type-arg]
    """Every conflict resolved by the companion, none by luck or by a precaution, none made
    worse, no false alarm; exactly the drones in ``climbers`` end flying higher -- by at least the
    offset, over segments the runs flagged, which come within the separation of another
    drone's path (what the runs compare is the protected volume: a segment near in space
    but not in time or altitude is no conflict)."""
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
    assert report["false_alarms"] == 0 and report["made_worse"] == 0
    assert report["precautionary_actions"] == 0, [
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
    assert report["ok"] and not report["problems"], report["problems"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "climbers", "conflicts"),
    [
        ("corridor", {1}, 1),
        ("no_conflict", set(), 0),
        ("three_drones", {1}, 2),
        ("ardupilot", {1}, 1),
        ("lossy_sf9", {1}, 1),
    ],
)
def test_scenario(name: str, climbers: set[int], conflicts: int) -> None:
    report = _replay(name)
    check(report, climbers)
    assert report["conflicts"] == conflicts
    if name == "lossy_sf9":
        assert report["link"]["profile"] == "eu868-sf9" and report["link"]["loss"] == 0.3


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "climbers", "conflicts"),
    [
        ("sep_parallel", {1}, 1),
        ("sep_tee", {1}, 1),
        ("sep_graze", {1}, 1),
        ("sep_higher5", {1}, 1),
        ("sep_first_leg", {1}, 1),
        ("sep_delayed", {1}, 1),
        ("sep_higher60", set(), 0),
        ("sep_later", set(), 0),
        ("sep_six", set(), 0),
    ],
)
def test_separation_scenario(name: str, climbers: set[int], conflicts: int) -> None:
    """Separation in space and time decides (scripts/make_separation_scenarios.py): near
    misses whose tracks never cross are conflicts and resolved at least the offset apart;
    a drone 5 m higher is climbed over clear of its altitude, never into it; a crossing 60 m
    apart in altitude, or minutes apart in time, is none -- no edit, no precaution; a first
    leg is flown at the offset from its start; a drone held up compares again."""
    report = _replay(name)
    check(report, climbers)
    assert report["conflicts"] == conflicts
    drones = {d["id"]: d for d in report["drones"]}
    if not conflicts:  # the runs found nothing: nobody flew differently
        assert all(not d["flagged_segments"] and not d["raises"] for d in drones.values())
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


@pytest.mark.slow
def test_crossing_as_a_user_runs_it(tmp_path: Path) -> None:
    """``make demo``'s replay with every output: the text summary says OK and exit 0; the JSON
    report, the PDF plot, the exports (CSV, KML, GeoJSON) and a JSON-lines log with the run's
    progress are all written."""
    out, plot, export, log = (tmp_path / n for n in ("r.json", "p.pdf", "exp", "log.jsonl"))
    flags = ["--out", out, "--plot", plot, "--export", export, "--log-json", log]
    run = subprocess.run(
        [sys.executable, "-m", "companion", "replay", SCENARIOS / "crossing.toml", *flags],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert run.returncode == 0, run.stdout + run.stderr[-3000:]
    last = run.stdout.strip().splitlines()[-1]  # "OK (with notes)" after a retried run
    assert re.match(r"OK( \(with notes\))?: every mission flown", last), last
    assert "MAVSDK version" not in run.stderr  # the library's chatter goes through logging
    report = json.loads(out.read_text())
    check(report, {1})
    assert report["conflicts"] == 1
    assert plot.read_bytes().startswith(b"%PDF")
    events = [json.loads(line) for line in log.read_text().splitlines()]
    kinds = [e.get("event") for e in events]
    assert {"run_started", "result", "uploaded", "answered"} <= set(kinds)
    progress = [e["fields"] for e in events if e.get("event") == "run_progress"]
    assert progress and all(p["sent_bytes"] >= 0 and p["elapsed_s"] > 0 for p in progress)
    assert any(p["role"] == "alice" and p["expected_bytes"] > 1000 for p in progress)
    rows = (export / "tracks.csv").read_text().splitlines()
    assert rows[0] == "drone,t_s,lat_deg,lon_deg,alt_m_amsl" and len(rows) > 100
    assert {row.split(",")[0] for row in rows[1:]} == {"1", "2"}
    geo = json.loads((export / "encounter.geojson").read_text())
    flagged = [f for f in geo["features"] if f["properties"]["kind"] == "flagged segment"]
    assert [f["properties"]["drone"] for f in flagged] == [1]
    lon, lat, _ = flagged[0]["geometry"]["coordinates"][0]
    assert 8 < lon < 9 and 47 < lat < 48  # GeoJSON order: longitude first
    kml = ElementTree.parse(export / "encounter.kml").getroot()
    names = [e.text or "" for e in kml.iter("{http://www.opengis.net/kml/2.2}name")]
    assert any("drone 1: flagged segment 0" in n for n in names)
    assert any(n.startswith("drones 1-2: closest approach") for n in names)


@pytest.mark.slow
def test_intruder_scenario() -> None:
    """Drone 3 flies for an operator nobody trusts: the crossing is resolved as without it;
    drones 1 and 2 never take it for a peer, report it once each and as an intruder (policy
    "alert"), and the report says the pairs with it were not deconflicted."""
    report = _replay("intruder")
    check(report, {1})
    assert report["conflicts"] == report["conflicts_resolved"] == 1
    assert report["untrusted_conflicts"] == 0  # it flies 40 m above everybody
    drones = {d["id"]: d for d in report["drones"]}
    rogue = drones[3]
    assert rogue["operator"] == "rogue" and not rogue["runs"]
    for ident in (1, 2):
        assert len(drones[ident]["untrusted_heard"]) == 1
        assert all(e["peer"] != 3 for e in drones[ident]["runs"])
    untrusted = [p for p in report["pairs"] if not p["trusted"]]
    assert sorted(p["drones"] for p in untrusted) == [[1, 3], [2, 3]]
    assert not any(p["acted"] or p["resolved"] for p in untrusted)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "climbing", "conflicts"),
    [
        ("inflight_crossing", 1, 1),
        ("inflight_headon", 1, 1),
        ("inflight_eu868", 1, 1),
        ("inflight_long", 1, 1),
        ("inflight_star", 2, 3),
    ],
)
def test_in_flight_scenario(name: str, climbing: int, conflicts: int) -> None:
    """Both (all) drones airborne from the start; the result must arrive in time.  Who is
    Alice to whom depends on take-off timing, so the test asks how many climb: one drone
    per pair stays, the others fly apart in altitude -- of three, one may need no climb of
    its own once another climbed clear of it for the third."""
    report = _replay(name)
    climbers = {d["id"] for d in report["drones"] if d["raises"]}
    assert 1 <= len(climbers) <= climbing
    check(report, climbers)  # two climbers at one height only when they are no conflict
    assert report["conflicts"] == conflicts
    for drone in report["drones"]:
        kinds = [e["kind"] for e in drone["timeline"]]
        if drone["id"] in climbers:  # when the run started, the result came, the edit landed
            assert {"run_started", "result", "uploaded"} <= set(kinds)


GOOD_DRONES = "[[drone]]\nid = 1\nmission = 'a.plan'\n[[drone]]\nid = 2\nmission = 'a.plan'\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("time_scale = 'fast'\n" + GOOD_DRONES, "time_scale: expected a number"),
        ("time_scale = 0\n" + GOOD_DRONES, "time_scale: 0 is out of range"),
        ("time_scale = nan\n" + GOOD_DRONES, "time_scale: nan is not a finite number"),
        ("time_scael = 10\n" + GOOD_DRONES, "unknown key 'time_scael' .did you mean 'time_scale'"),
        ("[link]\nprofile = 'eu433'\n" + GOOD_DRONES, r"\[link\]: profile: 'eu433' is not one"),
        ("[link]\nprofle = 'us915-sf9'\n" + GOOD_DRONES, "unknown key 'profle'"),
        ("[link]\nlos = 0.1\n" + GOOD_DRONES, "unknown key 'los' .did you mean 'loss'"),
        ("[link]\nloss = 1.5\n" + GOOD_DRONES, "loss: 1.5 is out of range"),
        ("[[drone]]\nid = 1\nmission = 'a.plan'\n", "at least two"),
        (GOOD_DRONES.replace("id = 1", "id = 1\ntakeof_delay_s = 5"), "drone 1: unknown key"),
        (GOOD_DRONES.replace("id = 2", "id = 1"), "drone 2: id: 1 is taken"),
        (GOOD_DRONES.replace("'a.plan'\n[", "'missing.plan'\n["), "drone 1: .*missing.plan"),
        ("not toml [", "bad.toml: not TOML"),
        (GOOD_DRONES.replace("id = 1", "id = 1\npause_at_s = 60"), "pause_at_s and pause_for_s go"),
        (GOOD_DRONES.replace("id = 1", "id = 1\npause_for_s = 60"), "pause_for_s: pause_at_s and"),
        (
            GOOD_DRONES.replace("id = 1", "id = 1\npause_at_s = 60\npause_for_s = 0"),
            "pause_for_s: 0 is out of range",
        ),
    ],
)
def test_bad_scenarios_are_refused(tmp_path: Path, text: str, message: str) -> None:
    """Every value checked, unknown keys named with the closest known one, the file named."""
    shutil.copy(SCENARIOS / "delivery_east.plan", tmp_path / "a.plan")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(ScenarioError, match=message):
        load_scenario(bad)
    bad.write_text(GOOD_DRONES)
    assert len(load_scenario(bad).drones) == 2  # the same file without the mistake is read


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
    report = asyncio.run(run_replay(scenario)).report.to_json()
    alice = report["drones"][0]
    assert alice["runs"] and alice["flagged_segments"] == []  # planned, but never applied
    assert any(f["kind"] == "upload_failed" for f in alice["failures"])
    assert alice["vehicle_holds"] == "original" and report["finished"]
    assert report["conflicts_resolved"] == 0  # honest: the vehicle could not be told


@pytest.mark.slow
def test_fault_peer_vanishes_mid_run() -> None:
    """Drone 2's companion vanishes while they compare (its drone flies on): drone 1's run
    fails, no result ever comes.  Once airborne, drone 1 cannot know where the silent peer
    is by now: with no run under way, the fail-safe's guard climbs over what it could reach."""
    # while they compare: at 35 s or, if discovery (with certificates, one to a few beacon
    # intervals) took longer, once drone 2 is answering
    scenario = _drone(_crossing(), 2, companion_stop_s=35.0, companion_stop_in_run=True)
    report = asyncio.run(run_replay(scenario)).report.to_json()
    alice = report["drones"][0]
    assert any(f["kind"] == "run_failed" for f in alice["failures"])
    assert not alice["runs"]  # no result
    assert all(e["why"].startswith("precaution") for e in alice["edits"])
    assert any(a["waiting"] for a in alice["precautionary"])
    assert report["finished"]  # the companion kept going and the missions were flown


@pytest.mark.slow
def test_fault_link_at_30_percent_loss() -> None:
    """At 30 % loss the comparison takes longer: drone 1 waits longer on the ground and
    drone 2 holds longer over the mast."""
    scenario = _crossing(loss=0.3, seed=9, time_scale=60.0, time_limit_s=1200.0)
    inspection = scenario.drones[1]
    longer = [it.replace(param1=700.0) if it.command == 19 else it for it in inspection.mission]
    scenario = _drone(_drone(scenario, 2, mission=longer), 1, takeoff_delay_s=400.0)
    report = asyncio.run(run_replay(scenario)).report.to_json()
    alice = report["drones"][0]
    assert alice["flagged_segments"] == alice["conflicting_segments"] == [0]
    assert alice["vehicle_holds"] == "edited"
    assert report["conflicts_resolved"] == report["conflicts"] == 1


def _in_flight(name: str, **changes: object) -> Scenario:
    scenario = load_scenario(SCENARIOS / f"{name}.toml")
    return dataclasses.replace(scenario, **changes)  # type: ignore[arg-type]


@pytest.mark.slow
def test_failsafe_climbs_when_the_result_cannot_arrive_in_time() -> None:
    """EU868 SF12 under the 1 % duty cycle: a first run takes hours of regulated airtime.
    Drone 1 sees it cannot know in time and climbs over what drone 2 can reach."""
    scenario = _in_flight("inflight_crossing", link_profile="eu868-sf12", time_limit_s=200.0)
    report = asyncio.run(run_replay(scenario)).report.to_json()
    alice = report["drones"][0]
    assert report["precautionary_actions"] >= 1
    action = alice["precautionary"][0]
    assert action["action"] == "climb" and action["needed_s"] > action["time_to_meet_s"]
    assert 1 in action["segments"]  # the leg over the crossing
    (pair,) = report["pairs"]
    assert pair["conflict"] and pair["acted"] and pair["resolved"]
    assert pair["closest_approach_m"] >= report["offset_m"] - RESOLVED_TOLERANCE_M
    assert not alice["runs"]  # no result: the precaution alone kept them apart


@pytest.mark.slow
def test_failsafe_acts_when_the_peer_falls_silent_mid_run() -> None:
    """In flight, drone 2's companion vanishes during the first run: no result will come.
    The overdue run and the silent peer (it may have flown on at cruise speed since it was
    last heard) make drone 1 climb before the crossing."""
    scenario = _drone(_in_flight("inflight_crossing", time_limit_s=120.0), 2, companion_stop_s=10.0)
    report = asyncio.run(run_replay(scenario)).report.to_json()
    alice = report["drones"][0]
    assert not alice["runs"], alice["timeline"]  # no result ever came
    (action,) = alice["precautionary"] or [alice["timeline"]]
    assert action["action"] == "climb" and 1 in action["segments"]  # the crossing leg
    (pair,) = report["pairs"]
    assert pair["conflict"] and pair["acted"] and pair["resolved"]


@pytest.mark.slow
def test_failsafe_hold_stops_before_the_segments_within_reach() -> None:
    scenario = _in_flight(
        "inflight_crossing",
        link_profile="eu868-sf12",
        time_limit_s=200.0,
        failsafe=Action.HOLD,
    )
    replay = asyncio.run(run_replay(scenario))
    report = replay.report.to_json()
    alice = report["drones"][0]
    assert alice["precautionary"][0]["action"] == "hold"
    assert any(e["kind"] == "hold" for e in alice["timeline"])
    (pair,) = report["pairs"]
    assert pair["acted"] and pair["closest_approach_m"] > 50  # drone 1 waited short of it
    assert not report["finished"]  # it holds until a result arrives


def test_replay_px4_flag_refuses_a_directory_that_is_no_px4_build(tmp_path: Path) -> None:
    """``--px4 DIR`` without bin/px4 and etc/: one line, exit 2, before anything starts."""
    crossing = str(SCENARIOS / "crossing.toml")
    run = subprocess.run(
        [sys.executable, "-m", "companion", "replay", crossing, "--px4", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines()[-1].startswith("error: PX4 SITL:")
    assert "Traceback" not in run.stderr and not run.stdout.strip()
