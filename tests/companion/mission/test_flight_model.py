"""The flight model flies as PX4 v1.16 SITL was measured to: within 1 m of altitude and 15 % of
time of PX4's tracks, compared at the same distance along the track.  The tracks are read
from ``../shared/px4-traces`` when it is beside the repository; the figures PX4 gave there
(quoted in that folder's README, and in docs/autopilot.md) are checked either way."""

from __future__ import annotations

import bisect
import csv
import itertools
import math
from pathlib import Path

import pytest

from companion.mission.files import read_mission_file
from companion.mission.flight_model import Flight, Kinematics, Reached, fly
from companion.mission.items import MissionItem
from protocol.geo.geodesy import ground_offset
from tests.companion.missions import item

TRACES = Path(__file__).resolve().parents[4] / "shared" / "px4-traces"
Track = list[tuple[float, float, float, float]]  # t, lat, lon, alt AMSL


def along(track: Track) -> list[float]:
    """Horizontal distance flown at each sample."""
    out, total = [0.0], 0.0
    for (_, la0, lo0, _), (_, la1, lo1, _) in itertools.pairwise(track):
        total += math.hypot(*ground_offset(la0, lo0, la1, lo1))
        out.append(total)
    return out


def at_distance(track: Track, distances: list[float], s: float) -> tuple[float, float]:
    """(time, altitude) when the track has flown ``s`` metres (first reached)."""
    k = min(bisect.bisect_left(distances, s), len(track) - 1)
    return track[k][0], track[k][3]


def compare(model: Track, px4: Track) -> tuple[float, float]:
    """Worst altitude difference (m) and worst relative time difference, at the same
    distance along the track, over PX4's samples while it moves along its legs."""
    dm, dp = along(model), along(px4)
    worst_alt = worst_time = 0.0
    for k in range(4, len(px4)):
        # along a leg: beyond the take-off, faster than 1 m/s over the last second (not
        # hovering, not climbing in place, where position noise alone adds distance)
        moving = dp[k] - dp[k - 4] > 1.0 and dp[k] > 10.0
        if not moving or dp[k] > dm[-1]:
            continue
        t_model, alt_model = at_distance(model, dm, dp[k])
        t_px4, alt_px4 = px4[k][0], px4[k][3]
        worst_alt = max(worst_alt, abs(alt_model - alt_px4))
        worst_time = max(worst_time, abs(t_model - t_px4) / t_px4)
    return worst_alt, worst_time


def read_px4(drone: str) -> Track:
    with (TRACES / "px4_tracks.csv").open() as handle:
        return [
            (float(r["t_s"]), float(r["lat_deg"]), float(r["lon_deg"]), float(r["alt_m_amsl"]))
            for r in csv.DictReader(handle)
            if r["drone"] == drone
        ]


def px4_flight(drone: str) -> tuple[list[MissionItem], Track, list[Reached], Track]:
    """PX4's mission for ``drone``, the model's flight of it (track, items reached) and
    PX4's track; skips where ``../shared`` is not beside the repository."""
    if not (TRACES / "px4_tracks.csv").is_file():
        pytest.skip("the PX4 SITL tracks are not beside the repository (../shared/px4-traces)")
    mission = read_mission_file(TRACES / f"d{drone}.plan")
    assert mission.home is not None
    model, reached = fly(mission.items, mission.home, Kinematics())
    return mission.items, model, reached, read_px4(drone)


@pytest.mark.parametrize("drone", ["1", "2"])
def test_the_model_flies_as_the_px4_tracks(drone: str) -> None:
    _, model, _, px4 = px4_flight(drone)
    worst_alt, worst_time = compare(model, px4)
    assert worst_alt <= 1.0, worst_alt
    assert worst_time <= 0.15, worst_time
    end = model[-1]  # the last waypoint: when does PX4 get there?
    there = next(
        t for t, la, lo, _ in px4 if math.hypot(*ground_offset(la, lo, end[1], end[2])) < 3
    )
    assert abs(end[0] - there) <= 0.15 * there, (end[0], there)


# What PX4 SITL did, as ../shared/px4-traces/README.md reports it (quoted): drone 1 takes off
# to 30 m, flies 300 m east at 30 m, 300 m on to a waypoint at 40 m, 300 m north at 40 m, 300 m
# west to a 20 s loiter at 25 m and turns back south-east at 25 m, at 8 m/s (DO_CHANGE_SPEED).
HOME = (47.3977, 8.5456, 488.0)


def _east(metres: float) -> float:
    return HOME[1] + metres / (111_320.0 * math.cos(math.radians(HOME[0])))


def _north(metres: float) -> float:
    return HOME[0] + metres / 111_195.0


def drone_one() -> list[MissionItem]:
    return [
        item(0, 22, HOME[0], HOME[1], 30.0),
        MissionItem(1, 2, 178, 0, 1, 1.0, 8.0, -1.0, 0.0, 0, 0, 0.0),
        item(2, 16, HOME[0], _east(300), 30.0),
        item(3, 16, HOME[0], _east(600), 40.0),
        item(4, 16, _north(300), _east(600), 40.0),
        item(5, 19, _north(300), _east(300), 25.0).replace(param1=20.0),
        item(6, 16, _north(100), _east(450), 25.0),
    ]


def test_the_model_gives_the_quoted_px4_figures() -> None:
    """Mid-leg 35.1 m at 86 s between waypoints at 30 and 40 m (a model that steps the
    altitude at the waypoint shows 40 m at 55 s); 39.6 m 10 m before the 40 m waypoint at
    105 s; 30.0 m 150 m east of the take-off at 46 s; the mission over after 258 s."""
    track, reached = fly(drone_one(), HOME)
    distances = along(track)
    for s, alt, t in ((150.0, 30.0, 46.0), (450.0, 35.1, 86.0), (590.0, 39.6, 105.0)):
        t_model, alt_model = at_distance(track, distances, s)
        assert abs(alt_model - HOME[2] - alt) <= 1.0, (s, alt_model - HOME[2])
        assert abs(t_model - t) <= 0.15 * t, (s, t_model)
    end = reached[-1].t
    assert abs(end - 258.0) <= 0.15 * 258.0, end
    loiter = next(r for r in reached if r.item == 5)
    assert loiter.left is not None and loiter.left - loiter.t == pytest.approx(20.0, abs=0.6)


def test_a_flight_predicts_what_it_will_fly() -> None:
    """The prediction from mid-flight is what the vehicle then flies: the same items at the
    same times (one model, stepped the same)."""
    flight = Flight(Kinematics(), HOME, drone_one())
    flight.start()
    for _ in range(400):  # 100 s in
        flight.step(0.25)
    done = len(flight.reached)
    predicted = flight.predict(dt=0.25)
    while flight.mission_running:
        flight.step(0.25)
    flown = flight.reached[done:]
    assert [r.item for r in predicted] == [r.item for r in flown]
    for p, f in zip(predicted, flown, strict=True):
        assert p.t == pytest.approx(f.t, abs=0.3)
        assert p.alt == pytest.approx(f.alt, abs=0.05)


def test_corners_slow_the_vehicle_and_straight_waypoints_do_not() -> None:
    """A right angle is flown at PX4's corner speed (1.7 m/s), a straight waypoint at cruise."""
    straight = [item(0, 22, HOME[0], HOME[1], 30.0), item(1, 16, HOME[0], _east(200), 30.0)]
    straight += [item(2, 16, HOME[0], _east(400), 30.0), item(3, 16, _north(200), _east(400), 30.0)]
    flight = Flight(Kinematics(cruise_m_s=8.0), HOME, straight)
    flight.start()
    speeds: dict[int, float] = {}
    while flight.mission_running:
        before = flight.current
        flight.step(0.1)
        if flight.current != before:
            speeds[before] = flight.speed
    assert speeds[1] > 7.0  # through the straight waypoint at cruise
    assert speeds[2] < 3.0  # round the corner (1.7 m/s at the waypoint, 2 m on)


@pytest.mark.parametrize("drone", ["1", "2"])
def test_the_model_reaches_every_waypoint_when_px4_did(drone: str) -> None:
    """Predicted from take-off, the model reaches each waypoint of the PX4 missions within
    2 s of PX4 SITL (measured: 1.1 s at most over 257 s of flight) -- the time PX4 came
    closest to it, or for a loiter the time it first came within 5 m (it then hovers there
    for the loiter's 20 s).  The relative figure above is largest in the first seconds; what
    the windows of a schedule rest on is this absolute error at the vertices."""
    items, _, reached, px4 = px4_flight(drone)
    checked = 0
    for r in reached:
        target = items[r.item]
        if target.command not in (16, 19):  # waypoints and timed loiters
            continue
        lat, lon = target.x / 1e7, target.y / 1e7
        distances = [(math.hypot(*ground_offset(la, lo, lat, lon)), t) for t, la, lo, _ in px4]
        if target.command == 19:
            there = next(t for d, t in distances if d < 5.0)
        else:
            there = min(distances)[1]
        assert abs(r.t - there) <= 2.0, (r.item, r.t, there)
        checked += 1
    assert checked >= 2
