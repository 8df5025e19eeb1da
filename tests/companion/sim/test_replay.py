"""The shipped scenarios end to end over the autopilot link: mock autopilots speaking
MAVLink, the real MAVSDK over UDP, companions on one simulated radio, flown in scaled time
(a paced clock).  Slow (tens of seconds each), part of ``make test``, run one at a time on
one worker (xdist group "realtime").  The rest of the scenarios fly in virtual time
(test_virtual_replay.py); these keep what only the link shows: transfers, an edit uploaded
in flight (an inserted waypoint), MAVSDK's mission pause, ArduPilot's personality over
MAVLink, a refused upload."""

from __future__ import annotations

import asyncio
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.runs.failsafe import Action
from companion.sim.mock_autopilot import Faults
from companion.sim.replay import run_replay
from companion.sim.scenario import ScenarioError, load_scenario
from tests.companion.sim.replay_checks import (
    SCENARIOS,
    Report,
    check,
    check_in_flight,
    check_separation,
    scenario,
    with_drone,
)

# real time, scaled: one replay at a time under ``make test``'s two workers
pytestmark = pytest.mark.xdist_group("realtime")


# In real time at 10-40x each protocol step's CPU counts 10-40 times its seconds of flight (a
# companion computer that much slower than this one), and MAVSDK's telemetry lags by as many
# seconds per second of a loaded machine: runs end later than on the virtual clock, and the
# fail-safe may act once where the virtual replays (CPU 1:1, test_virtual_replay.py) assert
# it never does (measured under make test: 1 precaution in about 1 of 3 suites, in the
# in-flight crossing at 10x or the crossing at 40x after a telemetry-lag retime).
REALTIME_PRECAUTIONS = 1


def _replay(name: str) -> Report:
    run = subprocess.run(
        [sys.executable, "-m", "companion", "replay", str(SCENARIOS / f"{name}.toml"), "--json"],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert run.returncode in (0, 1), run.stderr[-3000:]
    report: Report = json.loads(run.stdout)
    assert run.returncode == (0 if report["ok"] else 1)  # exit 0 only for a clean replay
    assert not report["virtual_time"]
    return report


@pytest.mark.slow
def test_ardupilot_scenario() -> None:
    """ArduPilot over MAVLink: its home is item 0, it reads frames back its own way, it keeps
    its current item on an upload."""
    report = _replay("ardupilot")
    check(report, {1}, precautions=REALTIME_PRECAUTIONS)
    assert report["conflicts"] == 1


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "climbing"),
    [("inflight_crossing", 1), ("sep_first_leg", 1)],
)
def test_in_flight_edits_over_mavsdk(name: str, climbing: int) -> None:
    """Edits uploaded in flight through MAVSDK, the vehicle's current item kept: the raised
    legs of the in-flight crossing, and a waypoint inserted on the first leg (a mission one
    item longer, its current item the new waypoint).  At 10x: at the scenario's 20-25x a
    CPU-starved machine delays MAVSDK's first telemetry by seconds of wall time, half a
    minute of flight, and the first result comes too late for the first leg."""
    report = asyncio.run(run_replay(scenario(name, time_scale=10.0))).report.to_json()
    assert not report["virtual_time"] and report["drones"][0]["vehicle"] == "mock"
    check_in_flight(report, climbing, 1, precautions=REALTIME_PRECAUTIONS)
    if name == "sep_first_leg":
        check_separation(report, name, {1}, 1, precautions=REALTIME_PRECAUTIONS)
        assert report["drones"][0]["vehicle_holds"] == "edited"


@pytest.mark.slow
def test_crossing_as_a_user_runs_it(tmp_path: Path) -> None:
    """``make demo``'s replay with every output: the text summary says OK and exit 0; the JSON
    report, the PDF plot, the exports (CSV, KML, GeoJSON) and a JSON-lines log with the run's
    progress are all written."""
    out, plot, export, log = (tmp_path / n for n in ("r.json", "p.pdf", "exp", "log.jsonl"))
    flags: list[str | Path] = ["--out", out, "--plot", plot, "--export", export, "--log-json", log]
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
    check(report, {1}, precautions=REALTIME_PRECAUTIONS)
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
        ("[link]\nchannels = 9\n" + GOOD_DRONES, "channels: 9 is out of range .us915-sf7 has 8"),
        ("[link]\nchannels = 0\n" + GOOD_DRONES, "channels: 0 is out of range"),
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


@pytest.mark.slow
def test_fault_rejected_upload_keeps_the_old_mission() -> None:
    crossing = scenario("crossing", time_scale=80.0)
    faulty = with_drone(crossing, 1, faults=Faults(reject_upload=mavlink.MAV_MISSION_NO_SPACE))
    report = asyncio.run(run_replay(faulty)).report.to_json()
    alice = report["drones"][0]
    assert alice["runs"] and alice["flagged_segments"] == []  # planned, but never applied
    assert any(f["kind"] == "upload_failed" for f in alice["failures"])
    assert alice["vehicle_holds"] == "original" and report["finished"]
    assert report["conflicts_resolved"] == 0  # honest: the vehicle could not be told


@pytest.mark.slow
def test_failsafe_hold_stops_before_the_segments_within_reach() -> None:
    """The hold: MAVSDK pauses the mission short of what the peer can reach."""
    holding = scenario(
        "inflight_crossing", link_profile="eu868-sf12", time_limit_s=200.0, failsafe=Action.HOLD
    )
    replay = asyncio.run(run_replay(holding))
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
