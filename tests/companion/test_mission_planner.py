"""Mission model and the altitude-offset planner (pure; hypothesis properties)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.mission import (
    MissionError,
    MissionItem,
    normalise,
    path_of,
    remaining,
    segments,
    vertices,
)
from companion.planner import OffsetSettings, PlannerError, plan_offsets

from .missions import HOME, item

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


@settings(max_examples=300, deadline=None)
@given(missions(), st.data(), st.booleans())
def test_planner_properties(items: list[MissionItem], data: st.DataObject, ardupilot: bool) -> None:
    v = vertices(items, ardupilot=ardupilot)
    nseg = max(len(v) - 1, 0)
    flagged = data.draw(st.sets(st.integers(0, nseg - 1))) if nseg else set()
    s = OffsetSettings(offset_m=10.0, max_altitude_m=200.0)
    out = plan_offsets(items, flagged, s, ardupilot=ardupilot)
    assert len(out) == len(items)
    moved = {v[k] for k in flagged} | {v[k + 1] for k in flagged}
    for index, (a, b) in enumerate(zip(items, out, strict=True)):
        # ground track, frames, commands and every non-positional item unchanged
        assert (a.x, a.y, a.frame, a.command, a.seq) == (b.x, b.y, b.frame, b.command, b.seq)
        if index in moved:
            assert b.z == pytest.approx(a.z + 10.0)
        else:
            assert a.same_as(b)
    for k, (i, j) in enumerate(segments(out, ardupilot=ardupilot)):
        if k in flagged:  # flown at the offset altitude
            assert (out[i].z, out[j].z) == pytest.approx((items[i].z + 10, items[j].z + 10))
        elif k - 1 in flagged and k + 1 not in flagged:  # first unflagged: back down at its end
            assert out[j].z == items[j].z
        elif k - 1 not in flagged and k + 1 not in flagged:  # unflagged: at planned altitude
            assert (out[i].z, out[j].z) == (items[i].z, items[j].z)
    if ardupilot:
        assert out[0] == items[0]


def test_vertices_skip_items_without_position_and_ardupilot_home() -> None:
    items = [
        item(0, 16, *HOME[:2], alt=HOME[2], frame=0),  # ArduPilot home
        item(1, 22, alt=20.0),  # takeoff here: no position
        item(2, 16, 47.398, 8.546),
        item(3, 178, frame=2, param1=8.0),  # speed change
        item(4, 19, 47.399, 8.546),  # loiter time at a position
        item(5, 21, 47.399, 8.547, alt=0.0),  # land at a position
        item(6, 20, frame=2),  # RTL
    ]
    assert vertices(items, ardupilot=True) == [2, 4, 5]
    assert vertices(items) == [0, 2, 4, 5]
    assert segments(items, ardupilot=True) == [(2, 4), (4, 5)]
    assert path_of(items, ardupilot=True)[0] == (473980000, 85460000)
    assert remaining(items, 4, ardupilot=True) == 0  # flying towards item 4: segment 0
    assert remaining(items, 5, ardupilot=True) == 1


def test_limits_are_errors_not_clips() -> None:
    items = [item(0, 16, 47.398, 8.546, 115.0), item(1, 16, 47.399, 8.546, 30.0)]
    with pytest.raises(PlannerError, match="above the maximum altitude 120"):
        plan_offsets(items, {0}, OffsetSettings(max_altitude_m=120.0))
    with pytest.raises(PlannerError, match="below the minimum"):
        plan_offsets(items, {0}, OffsetSettings(direction="down", offset_m=30.0))
    with pytest.raises(PlannerError, match="outside"):
        plan_offsets(items, {1}, OffsetSettings())
    amsl = [item(0, 16, 47.398, 8.546, 600.0, frame=0), item(1, 16, 47.399, 8.546, 600.0, 0)]
    assert plan_offsets(amsl, {0})[0].z == 610.0  # AMSL: no height limit unless given
    with pytest.raises(PlannerError, match="AMSL"):
        plan_offsets(amsl, {0}, OffsetSettings(max_altitude_amsl_m=605.0))
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
