"""The flown ground path: launch leg, RTL, DO_JUMP loops, loiter circles, fixed items."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.mission.flightpath import VertexKind, flight_order, flight_path
from companion.mission.items import MissionError, MissionItem
from companion.mission.planner import fixed_segments, plan_offsets
from protocol.geo.geodesy import moved
from protocol.geo.geometry import path_hits
from tests.companion.missions import HOME, item

HOME_E7 = (round(HOME[0] * 1e7), round(HOME[1] * 1e7))


def at(north_m: float, east_m: float) -> tuple[float, float]:
    """The point ``north_m``, ``east_m`` from home in the project's one Earth model (WGS84,
    as the loiter polygons are made: a sphere of 111 195 m per degree put points 0.2 % off,
    0.7 m at 376 m, outside a polygon that circumscribes the circle by 0.9 m)."""
    return moved(HOME[0], HOME[1], north_m, east_m)


def e7(north_m: float, east_m: float) -> tuple[int, int]:
    lat, lon = at(north_m, east_m)
    return round(lat * 1e7), round(lon * 1e7)


def jump(seq: int, target: int, repeat: int) -> MissionItem:
    return item(seq, 177, frame=2, param1=float(target)).replace(param2=float(repeat))


def test_launch_leg_and_rtl_leg() -> None:
    items = [
        item(0, 22, alt=20.0),  # take off here: no position of its own
        item(1, 16, *at(0, 300)),
        item(2, 16, *at(300, 300)),
        item(3, 20, frame=2),  # RTL
    ]
    path = flight_path(items, HOME_E7)
    assert path.points == [HOME_E7, e7(0, 300), e7(300, 300), HOME_E7]
    kinds = [v.kind for v in path.vertices]
    assert kinds == [VertexKind.HOME, VertexKind.POSITION, VertexKind.POSITION, VertexKind.HOME]
    assert path.items_of(0) == [1]  # the launch leg: only the waypoint may move
    assert path.items_of(2) == [2]  # the way home: the last waypoint
    assert flight_path(items, None).points == [e7(0, 300), e7(300, 300)]  # home unknown


def test_takeoff_and_land_are_never_moved() -> None:
    items = [
        item(0, 22, *at(0, 0), alt=20.0),  # take off at home's position
        item(1, 16, *at(0, 300)),
        item(2, 21, *at(0, 600), alt=0.0),  # land there
    ]
    path = flight_path(items, HOME_E7)
    assert path.points == [HOME_E7, e7(0, 300), e7(0, 600)]  # home and take-off: one vertex
    assert path.vertices[0].items == (0,) and path.vertices[0].moves == ()
    out = plan_offsets(items, {0, 1}, path=path)
    assert [b.z - a.z for a, b in zip(items, out, strict=True)] == [0.0, 10.0, 0.0]
    # a leg between two fixed vertices cannot be raised: say so
    short = [item(0, 22, *at(0, 0), alt=20.0), item(1, 21, *at(0, 100), alt=0.0)]
    short_path = flight_path(short, HOME_E7)
    assert fixed_segments(short_path, {0}) == [0]


def test_do_jump_loop_is_flown_with_its_leg_back() -> None:
    a, b, c, d = at(0, 100), at(0, 400), at(300, 400), at(300, 100)
    items = [
        item(0, 16, *a),
        item(1, 16, *b),
        item(2, 16, *c),
        jump(3, 1, 2),  # back to item 1, twice
        item(4, 16, *d),
    ]
    assert flight_order(items) == [0, 1, 2, 3, 1, 2, 3, 4]  # the path takes it once
    assert flight_order(items, max_jumps=None) == [0, 1, 2, 3, 1, 2, 3, 1, 2, 3, 4]
    path = flight_path(items, None)
    assert path.points == [e7(*x) for x in ((0, 100), (0, 400), (300, 400))] + [
        e7(0, 400),  # the leg back to the jump's target
        e7(300, 400),
        e7(300, 100),
    ]
    # a path crossing only the leg back (from c to b) is seen
    other = [(e7(150, 300)), (e7(150, 500))]
    assert any(path_hits(path.points, other))
    with pytest.raises(MissionError, match="DO_JUMP"):
        flight_path([item(0, 16, *a), jump(1, 7, 1)], None)


def test_jump_forever_and_nested_loops_are_bounded() -> None:
    items = [item(0, 16, *at(0, 0)), item(1, 16, *at(0, 100)), jump(2, 0, -1)]
    assert flight_order(items) == [0, 1, 2, 0, 1, 2]
    assert len(flight_order(items, max_jumps=None, limit=100)) == 100
    nested = [
        item(0, 16, *at(0, 0)),
        item(1, 16, *at(0, 100)),
        jump(2, 1, 3),
        item(3, 16, *at(100, 100)),
        jump(4, 0, 2),
    ]
    order = flight_order(nested, max_jumps=None)
    # the inner jump's count is not reset by the outer loop (as on PX4 and ArduPilot)
    assert order.count(4) == 3 and order.count(2) == 6


def test_loiter_circle_is_a_polygon_around_it() -> None:
    items = [item(0, 16, *at(0, 0)), item(1, 19, *at(0, 500)).replace(param3=80.0)]
    path = flight_path(items, None)
    corners = [v for v in path.vertices if v.kind is VertexKind.LOITER]
    assert len(corners) == 9  # eight corners, closed
    assert all(v.moves == (1,) for v in corners)
    # a path passing 70 m north of the centre crosses the 80 m circle: it must be seen
    other = [e7(70, 300), e7(70, 700)]
    assert any(path_hits(path.points, other))
    # without a radius (a multicopter hovers) the loiter is its point
    hover = [items[0], items[1].replace(param3=0.0)]
    assert not any(path_hits(flight_path(hover, None).points, other))


@settings(max_examples=200, deadline=None)
@given(st.floats(5.0, 400.0), st.floats(0.0, 2 * math.pi), st.floats(0.0, 0.999))
def test_loiter_polygon_covers_the_circle(radius: float, angle: float, frac: float) -> None:
    """Any point of the circle lies inside the polygon: a chord from the centre to a point
    just outside the circle crosses the polygon's boundary."""
    items = [item(0, 19, *at(0, 0)).replace(param3=radius)]
    ring = [v.point for v in flight_path(items, None).vertices if v.kind is VertexKind.LOITER]
    inside = e7(radius * frac * math.cos(angle), radius * frac * math.sin(angle))
    on_circle = e7(radius * math.cos(angle), radius * math.sin(angle))
    assert not any(path_hits(ring, [e7(0, 0), inside]))
    assert not any(path_hits(ring, [e7(0, 0), on_circle]))  # the circle is inside the ring


def test_ardupilot_home_is_item_0_and_start_at() -> None:
    items = [
        item(0, 16, *HOME[:2], alt=HOME[2], frame=0),  # ArduPilot home
        item(1, 22, alt=20.0),  # takeoff here: no position
        item(2, 16, 47.398, 8.546),
        item(3, 178, frame=2, param1=8.0),  # speed change
        item(4, 19, 47.399, 8.546),  # loiter time at a position (no radius)
        item(5, 21, 47.399, 8.547, alt=0.0),  # land at a position
    ]
    path = flight_path(items, None, ardupilot=True)
    assert path.points[0] == HOME_E7 and path.vertices[0].kind is VertexKind.HOME
    assert [v.items for v in path.vertices] == [(), (2,), (4,), (5,)]
    assert path.start_at(2) == 0  # flying towards item 2: the launch leg
    assert path.start_at(3) == 1  # a speed change: the next leg
    assert path.start_at(5) == 2


def test_a_home_a_few_centimetres_off_the_take_off_point_is_the_same_place() -> None:
    """PX4 SITL's HOME_POSITION came back 3 cm from the home it was given: the take-off at
    home must not become a leg of its own (it would shift every segment number)."""
    items = [item(0, 22, *at(0, 0), 20.0), item(1, 16, *at(0, 300)), item(2, 16, *at(1.5, 300))]
    px4_home = e7(0.03, -0.02)
    path = flight_path(items, px4_home)
    assert [v.items for v in path.vertices] == [(0,), (1,), (2,)]
    assert path.vertices[0].kind is VertexKind.HOME and path.vertices[0].point == px4_home
    assert path.segments == 2  # 1.5 m apart is a leg
