"""Mission model and the altitude-offset planner (pure; hypothesis properties)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.mission.flightpath import MOVABLE, flight_path
from companion.mission.items import MissionError, MissionItem, normalise
from companion.mission.planner import (
    OffsetSettings,
    PlannerError,
    Vehicle,
    fixed_segments,
    plan_edit,
    plan_offsets,
)
from tests.companion.missions import HOME, item

COMMANDS = [16, 16, 16, 17, 19, 21, 22, 82, 20, 178, 183, 206]
FRAMES = [6, 6, 3, 0, 5, 10, 11, 2]


@st.composite
def missions(draw: st.DrawFn) -> list[MissionItem]:
    n = draw(st.integers(1, 40))
    out = []
    for i in range(n):
        command = draw(st.sampled_from(COMMANDS))
        frame = 2 if command in (178, 183, 206, 20) else draw(st.sampled_from(FRAMES[:-1]))
        lat = HOME[0] + draw(st.floats(-0.01, 0.01))
        lon = HOME[1] + draw(st.floats(-0.01, 0.01))
        alt = draw(st.floats(10, 60)) + (HOME[2] if frame in (0, 5) else 0)
        out.append(item(i, command, lat, lon, alt, frame))
    return out


HOME_E7 = (round(HOME[0] * 1e7), round(HOME[1] * 1e7))


@settings(max_examples=300, deadline=None)
@given(missions(), st.data(), st.booleans())
def test_planner_properties(items: list[MissionItem], data: st.DataObject, ardupilot: bool) -> None:
    path = flight_path(items, HOME_E7, ardupilot=ardupilot)
    nseg = path.segments
    flagged = data.draw(st.sets(st.integers(0, nseg - 1))) if nseg else set()
    s = OffsetSettings(offset_m=10.0, max_altitude_m=200.0)
    out = plan_offsets(items, flagged, s, path=path)
    assert len(out) == len(items)
    moved = {i for k in flagged for i in path.items_of(k)}
    for index, (a, b) in enumerate(zip(items, out, strict=True)):
        # ground track, frames, commands and every non-positional item unchanged
        assert (a.x, a.y, a.frame, a.command, a.seq) == (b.x, b.y, b.frame, b.command, b.seq)
        if index in moved:
            assert a.command in MOVABLE  # take-off, landing, RTL and DO_ items never move
            assert b.z == pytest.approx(a.z + 10.0)
        else:
            assert a.same_as(b)
    vs = path.vertices
    for k in range(nseg):
        ends = [i for v in (vs[k], vs[k + 1]) for i in v.moves]
        if k in flagged:  # every movable end flown at the offset altitude
            assert all(out[i].z == pytest.approx(items[i].z + 10) for i in ends)
        elif k - 1 not in flagged and k + 1 not in flagged:  # unflagged: at planned altitude
            assert all(out[i].z == items[i].z for i in ends if i not in moved)
    assert set(fixed_segments(path, flagged)) == {k for k in flagged if not path.items_of(k)}
    if ardupilot:
        assert out[0] == items[0]


def test_limits_are_errors_not_clips() -> None:
    items = [item(0, 16, 47.398, 8.546, 115.0), item(1, 16, 47.399, 8.546, 30.0)]
    path = flight_path(items, None)

    def plan(items: list[MissionItem], flagged: set[int], s: OffsetSettings) -> list[MissionItem]:
        return plan_offsets(items, flagged, s, path=flight_path(items, None))

    with pytest.raises(PlannerError, match="above the maximum altitude 120"):
        plan(items, {0}, OffsetSettings(max_altitude_m=120.0))
    with pytest.raises(PlannerError, match="below the minimum"):
        plan(items, {0}, OffsetSettings(direction="down", offset_m=30.0))
    with pytest.raises(PlannerError, match="outside"):
        plan_offsets(items, {1}, OffsetSettings(), path=path)
    amsl = [item(0, 16, 47.398, 8.546, 600.0, frame=0), item(1, 16, 47.399, 8.546, 600.0, 0)]
    assert plan(amsl, {0}, OffsetSettings())[0].z == 610.0  # AMSL: no height limit unless given
    with pytest.raises(PlannerError, match="AMSL"):
        plan(amsl, {0}, OffsetSettings(max_altitude_amsl_m=605.0))
    with pytest.raises(PlannerError):
        OffsetSettings(offset_m=-1)


def test_normalise_and_checks() -> None:
    items = [item(5, 16, 47.398, 8.546).replace(current=1), item(9, 16, 47.399, 8.546)]
    items[1] = items[1].replace(current=1)
    out = normalise(items)
    assert [i.seq for i in out] == [0, 1] and [i.current for i in out] == [1, 0]
    with pytest.raises(MissionError, match="latitude"):
        normalise([item(0, 16, 95.0, 8.0)])
    with pytest.raises(MissionError, match="frame"):
        normalise([item(0).replace(frame=99)])
    with pytest.raises(MissionError, match="not a number"):
        normalise([item(0, 16, 47.0, 8.0).replace(z=math.inf)])


EAST = 0.004  # degrees of longitude: about 300 m at HOME's latitude


def route() -> list[MissionItem]:
    """Take-off to 30 m, three waypoints 300 m apart going east, a DO_JUMP back to the
    second waypoint once, a landing."""
    lat, lon = HOME[0], HOME[1]
    items = [item(0, 22, lat, lon, 30.0)]
    items += [item(i, 16, lat, lon + i * EAST, 30.0) for i in (1, 2, 3)]
    jump = item(4, 177, frame=2).replace(param1=2.0, param2=1.0)
    return [*items, jump, item(5, 21, lat, lon + 3 * EAST, 0.0)]


def test_edit_on_the_ground_raises_the_take_off() -> None:
    """Before take-off the first leg starts at the take-off's altitude: a raise of the leg
    from the take-off point lifts the take-off item too (the whole leg at the raise)."""
    items = route()
    path = flight_path(items, HOME_E7)
    first = next(k for k in range(path.segments) if 0 in path.vertices[k].items)
    ground = Vehicle(None, *HOME_E7, 0.0, HOME[2])
    edit = plan_edit(items, {first: 15.0}, OffsetSettings(), path=path, vehicle=ground)
    assert edit.inserted is None and edit.origin == tuple(range(len(items)))
    assert edit.items[0].z == 45.0  # the take-off
    ends = {i for v in (path.vertices[first], path.vertices[first + 1]) for i in v.items}
    assert all(edit.items[i].z == items[i].z + 15.0 for i in ends if items[i].command == 16)


def test_edit_in_flight_inserts_a_waypoint_ahead_on_the_raised_leg() -> None:
    """In flight on the raised leg, below its new altitude: a waypoint at the raised
    altitude is inserted ahead (by the lead the climb needs), the vehicle's leg is split
    there, every later item moves on by one and the DO_JUMP follows its target."""
    items = route()
    path = flight_path(items, HOME_E7)
    k = path.start_at(2)  # flying to waypoint 2
    here = (HOME_E7[0], HOME_E7[1] + round(1.2 * EAST * 1e7))
    vehicle = Vehicle(k, *here, 30.0, HOME[2] + 30.0, lead_per_m=3.0)
    edit = plan_edit(items, {k: 10.0}, OffsetSettings(), path=path, vehicle=vehicle)
    assert edit.inserted == 2
    new = edit.items[2]
    assert new.command == 16 and new.z == 40.0
    assert HOME_E7[1] < here[1] < new.y < items[2].y  # between the vehicle and the target
    assert new.y - here[1] == pytest.approx(30.0 / 300.0 * EAST * 1e7, rel=0.05)  # 3 m/m x 10
    assert edit.origin == (0, 1, 2, 2, 3, 4, 5)
    assert [it.seq for it in edit.items] == list(range(len(items) + 1))
    assert edit.items[5].command == 177 and edit.items[5].param1 == 3.0  # the jump follows
    assert edit.index_of(2) == 3 and edit.index_of(5) == 6
    # already at the raised altitude: nothing inserted
    high = Vehicle(k, *here, 40.0, HOME[2] + 40.0, lead_per_m=3.0)
    assert plan_edit(items, {k: 10.0}, OffsetSettings(), path=path, vehicle=high).inserted is None
    # a raise of another segment: nothing inserted either
    other = plan_edit(items, {k + 1: 10.0}, OffsetSettings(), path=path, vehicle=vehicle)
    assert other.inserted is None
