"""Mission files: .plan and QGC WPL 110, round trips and clear errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from companion.mission.files import (
    format_plan,
    format_wpl,
    parse_plan_file,
    parse_plan_items,
    parse_wpl,
    parse_wpl_file,
    read_mission,
    read_mission_file,
)
from companion.mission.flightpath import MOVABLE, flight_path
from companion.mission.items import MissionError
from companion.mission.personalities import ARDUPILOT, PX4, UnsupportedItem
from companion.mission.planner import plan_offsets
from protocol.tools.cli import write_atomic
from tests.companion.missions import HOME, item, survey


def test_round_trips(tmp_path: Path) -> None:
    items = survey(23)
    items[0] = items[0].replace(current=1)
    write_atomic(tmp_path / "m.plan", format_plan(items, HOME))
    write_atomic(tmp_path / "m.txt", format_wpl(items, HOME))
    for name in ("m.plan", "m.txt"):
        back = read_mission(tmp_path / name)
        assert len(back) == len(items)
        assert all(a.same_as(b) for a, b in zip(items, back, strict=True))
    assert not list(tmp_path.glob(".m.*"))  # no temporary files left behind


def test_plan_nan_params_survive() -> None:
    items, home = parse_plan_items(format_plan(survey(3), HOME))
    assert math.isnan(items[0].param4) and home == HOME


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.pop("mission"), "no mission.items"),
        (lambda d: d["mission"]["items"][1].update(type="ComplexItem"), "mission item 1"),
        (lambda d: d["mission"]["items"][2].update(params=[0, 0]), "item 2: params"),
        (lambda d: d["mission"]["items"][0]["params"].__setitem__(4, 123.0), "item 0"),
        (lambda d: d["mission"]["items"][0].update(command="16"), "must be integers"),
        (lambda d: d["mission"].update(items=[]), "no items"),
    ],
)
def test_plan_errors_name_the_item(mutate, message: str) -> None:  # type: ignore[no-untyped-def]
    doc = json.loads(format_plan(survey(4), HOME))
    mutate(doc)
    with pytest.raises(MissionError, match=message):
        parse_plan_items(json.dumps(doc))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("QGC WPL 100\n", "line 1"),
        ("QGC WPL 110\n0\t1\t0\t16\n", "line 2: expected 12 fields"),
        ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\tx\t8.5\t30\t1\n", "line 2"),
        (
            "QGC WPL 110\n1\t1\t0\t16\t0\t0\t0\t0\t47.3\t8.5\t30\t1\n"
            "1\t0\t3\t16\t0\t0\t0\t0\t47.3\t8.5\t30\t1\n",
            "sequence number 1 after 1",
        ),
        ("QGC WPL 110\n0\t1\t42\t16\t0\t0\t0\t0\t47.3\t8.5\t30\t1\n", "unknown frame"),
    ],
)
def test_wpl_errors_name_the_line(text: str, message: str) -> None:
    with pytest.raises(MissionError, match=message):
        parse_wpl(text)


def test_mission_show_cli(tmp_path: Path) -> None:
    path = tmp_path / "m.txt"
    path.write_text(format_wpl(survey(7), HOME))
    run = subprocess.run(
        [sys.executable, "-m", "companion", "mission", "show", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stderr
    # item 0 stands at home: the launch leg is home -> item 1
    assert "segment 0: home (item 0) -> position (item 1)" in run.stdout
    assert "DO_CHANGE_SPEED" in run.stdout
    bad = tmp_path / "bad.txt"
    bad.write_text("QGC WPL 110\n0\t1\n")
    run = subprocess.run(
        [sys.executable, "-m", "companion", "mission", "show", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2 and "line 2" in run.stderr


# ---------------------------------------------------------------- missions as others write them

FILES = Path(__file__).parent / "mission_files"
TAKEOFF, LAND, RTL, LOITER_TO_ALT = 22, 21, 20, 31


@pytest.mark.parametrize(
    ("name", "ardupilot", "n_items", "n_vertices", "kinds"),
    [
        # take-off at home merges with home; three waypoints; RTL back home
        ("px4_takeoff_rtl.plan", False, 5, 5, "HPPPH"),
        # the patrol loop once more and the leg back to its start, then the landing
        ("patrol_do_jump.plan", False, 6, 7, "HPPPPPP"),
        # take-off point, waypoint, an 80 m loiter circle and a 120 m loiter (as polygons)
        (
            "loiters_fixed_wing.plan",
            False,
            4,
            25,
            "HPP" + "P" + "L" * 9 + "P" + "P" + "L" * 9 + "P",
        ),
        ("terrain_frame.plan", True, 5, 4, "HPPH"),
        # QGC's generated survey items are flown: 12 waypoints between home and home
        ("survey_complex.plan", False, 16, 14, "H" + "P" * 12 + "H"),
        # a structure scan: entrance, two closed rings, exit
        ("structure_scan.plan", False, 14, 11, "H" + "P" * 9 + "H"),
        ("fw_landing_pattern.plan", False, 5, 15, "HPP" + "P" + "L" * 9 + "P" + "P"),
        ("ardupilot_home.waypoints", True, 6, 5, "HPPPH"),
        ("commented_from_one.waypoints", False, 3, 3, "HPP"),
    ],
)
def test_real_mission_files_fly_their_whole_path(
    name: str, ardupilot: bool, n_items: int, n_vertices: int, kinds: str
) -> None:
    plan = read_mission_file(FILES / name)
    items = plan.for_autopilot(ardupilot=ardupilot)
    assert len(items) == n_items
    path = flight_path(items, plan.home_degE7, ardupilot=ardupilot)
    assert len(path.vertices) == n_vertices
    assert "".join(v.kind.name[0] for v in path.vertices) == kinds
    assert path.points[0] == plan.home_degE7  # the launch leg starts at home
    # raise everything: waypoints and loiters move, take-off, landing, RTL, DO_ and home never
    out = plan_offsets(items, range(path.segments), path=path)
    for a, b in zip(items, out, strict=True):
        if a.command in MOVABLE and a.has_position and not (ardupilot and a.seq == 0):
            assert b.z == a.z + 10.0, a
        else:
            assert b == a, a
    assert all(math.isfinite(it.z) for it in items)


def test_home_of_a_wpl_is_its_first_item() -> None:
    plan = read_mission_file(FILES / "ardupilot_home.waypoints")
    assert plan.home == pytest.approx((HOME[0], HOME[1], HOME[2]))
    assert plan.items[0].command == TAKEOFF  # item 0 of the mission, home excluded
    assert [it.seq for it in plan.for_autopilot(ardupilot=True)] == list(range(6))
    assert read_mission_file(FILES / "commented_from_one.waypoints").items[-1].command == LAND


def test_plan_home_is_not_the_takeoff_item_on_ardupilot() -> None:
    plan = read_mission_file(FILES / "px4_takeoff_rtl.plan")
    items = plan.for_autopilot(ardupilot=True)
    assert items[0].command == 16 and (items[0].x, items[0].y) == plan.home_degE7
    assert items[1].command == TAKEOFF


def test_null_altitude_is_the_height_above_terrain_or_an_error_never_zero() -> None:
    """QGC's "calculated above terrain" item without terrain data stores a null altitude and
    keeps the height above terrain (``Altitude``): that is the terrain frame, which ArduPilot
    flies and PX4 refuses before anything is sent.  Without ``Altitude``: an error."""
    mission = read_mission_file(FILES / "terrain_null_altitude.plan")
    item = mission.items[1]
    assert (item.frame, item.z) == (10, 40.0)
    with pytest.raises(UnsupportedItem, match="item 1: PX4 refuses frame 10 \\(above terrain"):
        PX4.check(mission.for_autopilot())
    ARDUPILOT.check(mission.for_autopilot(ardupilot=True))
    doc = json.loads((FILES / "terrain_null_altitude.plan").read_text())
    del doc["mission"]["items"][1]["Altitude"]
    with pytest.raises(MissionError, match=r"mission item 1: altitude is null \(QGroundControl"):
        parse_plan_file(json.dumps(doc))


def test_waypoint_without_position_is_an_error() -> None:
    doc = json.loads((FILES / "px4_takeoff_rtl.plan").read_text())
    doc["mission"]["items"][2]["params"][4] = None
    with pytest.raises(MissionError, match="item 2: command 16 needs a latitude"):
        parse_plan_file(json.dumps(doc))


def test_structure_scan_ring_is_outside_the_structure() -> None:
    items = read_mission_file(FILES / "structure_scan.plan").items
    ring = [(it.x, it.y) for it in items[2:6]]  # the first layer's corners
    lat0 = HOME[0]
    k_e = 111_195.0 * math.cos(math.radians(lat0))
    corners = sorted(
        (round((x / 1e7 - HOME[0]) * 111_195.0), round((y / 1e7 - HOME[1]) * k_e)) for x, y in ring
    )
    # the 60 m square at 200..260 m pushed 20 m out: 180..280 m
    assert corners == [(180, 180), (180, 280), (280, 180), (280, 280)]
    assert {it.z for it in items[1:-2]} == {17.5, 32.5, 40.0}  # layer middles and entrance


def test_px4_refuses_what_it_cannot_fly_before_upload() -> None:
    from companion.mission.personalities import ARDUPILOT, PX4

    plan = read_mission_file(FILES / "terrain_frame.plan")
    assert any("frame 10" in p for p in PX4.problems(plan.items))
    assert not ARDUPILOT.problems(plan.for_autopilot(ardupilot=True))
    wpl = read_mission_file(FILES / "ardupilot_home.waypoints")
    assert any("0,0" in p for p in PX4.start_problems(wpl.items))  # take-off "here"
    px4 = wpl.for_autopilot()  # for PX4 the take-off gets home's position
    assert not PX4.start_problems(px4) and (px4[0].x, px4[0].y) == wpl.home_degE7


def _jump_plan(ids: list[int], jump_to: int) -> str:
    items = [
        {
            "type": "SimpleItem",
            "command": 16,
            "frame": 3,
            "doJumpId": k,
            "params": [0, 0, 0, None, 47.3977 + 0.001 * n, 8.5456, 30],
        }
        for n, k in enumerate(ids)
    ]
    items.append(
        {
            "type": "SimpleItem",
            "command": 177,
            "frame": 2,
            "doJumpId": 99,
            "params": [jump_to, 1, 0, 0, 0, 0, 0],
        }
    )
    return json.dumps(
        {
            "fileType": "Plan",
            "mission": {"items": items, "plannedHomePosition": [47.3977, 8.5456, 488]},
        }
    )


def test_plan_do_jump_names_its_target_by_do_jump_id() -> None:
    """QGroundControl's DO_JUMP param1 is the target's doJumpId, whatever the numbering."""
    mission = parse_plan_file(_jump_plan([20, 30, 40], 30))
    assert mission.items[3].param1 == 1  # the item with doJumpId 30, numbered without home
    path = flight_path(mission.for_autopilot(), mission.home_degE7)
    assert [v.items for v in path.vertices] == [(0,), (1,), (2,), (1,), (2,)]
    ardupilot = mission.for_autopilot(ardupilot=True)
    assert ardupilot[4].param1 == 2  # ArduPilot numbers home as item 0
    assert path.points == flight_path(ardupilot, None, ardupilot=True).points
    with pytest.raises(MissionError, match="mission item 3: DO_JUMP to doJumpId 35"):
        parse_plan_file(_jump_plan([20, 30, 40], 35))


def test_wpl_do_jump_counts_home_as_item_0_and_round_trips(tmp_path: Path) -> None:
    text = "\n".join(
        [
            "QGC WPL 110",
            "0\t1\t0\t16\t0\t0\t0\t0\t47.3977\t8.5456\t488\t1",
            "1\t0\t3\t16\t0\t0\t0\t0\t47.3987\t8.5456\t30\t1",
            "2\t0\t3\t16\t0\t0\t0\t0\t47.3987\t8.5466\t30\t1",
            "3\t0\t3\t16\t0\t0\t0\t0\t47.3977\t8.5466\t30\t1",
            "4\t0\t0\t177\t2\t1\t0\t0\t0\t0\t0\t1",
        ]
    )
    mission = parse_wpl_file(text)
    assert mission.items[3].param1 == 1  # line 2 of the file is item 1 without home
    order = [v.items[0] for v in flight_path(mission.for_autopilot(), None).vertices]
    assert order == [0, 1, 2, 1, 2]
    assert mission.for_autopilot(ardupilot=True)[4].param1 == 2
    for fmt, read in ((format_wpl, parse_wpl_file), (format_plan, parse_plan_file)):
        out = tmp_path / "again"
        write_atomic(out, fmt(mission.items, mission.home or ()))
        again = read(out.read_text())
        assert [it.param1 for it in again.items] == [it.param1 for it in mission.items]


def test_ardupilot_do_jump_tag_loops_to_its_jump_tag() -> None:
    """ArduPilot's DO_JUMP_TAG (601) continues at the JUMP_TAG (600) with its tag."""
    items = [
        item(0, 16, 47.3977, 8.5456, 488.0, frame=0),  # home
        item(1, 600, frame=2, param1=7.0),  # JUMP_TAG 7
        item(2, 16, 47.3987, 8.5456),
        item(3, 16, 47.3987, 8.5466),
        item(4, 601, frame=2, param1=7.0).replace(param2=1.0),  # DO_JUMP_TAG 7, once
        item(5, 16, 47.3977, 8.5466),
    ]
    order = [v.items for v in flight_path(items, None, ardupilot=True).vertices]
    assert order == [(), (2,), (3,), (2,), (3,), (5,)]  # home (item 0), the loop once more
    with pytest.raises(MissionError, match=r"DO_JUMP_TAG to tag 8\.0"):
        flight_path([*items[:4], items[4].replace(param1=8.0)], None, ardupilot=True)
