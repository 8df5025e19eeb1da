"""The autopilot personalities against what PX4 v1.16 SITL was measured to do
(``docs/px4-sitl-findings.md``) and what ArduPilot documents."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.mission.items import MissionItem
from companion.mission.personalities import ARDUPILOT, PX4, Param, Refusal, UnsupportedItem
from tests.companion.missions import item

NAN = math.nan
SAMPLES = (NAN, 2.5, -7.0, 400.0)


def _with(command: int, name: str, value: float, frame: int = 3) -> MissionItem:
    base = item(1, command, 47.4, 8.5, 30.0, frame=frame).replace(param4=0.0)
    if command == 177:
        base = base.replace(param1=1.0, param2=1.0)
    return base.replace(**{name: value})


# The "parameters on read-back" table of docs/px4-sitl-findings.md, row by row.
PX4_ROWS: dict[tuple[int, str], tuple[float, float, float, float]] = {
    (16, "param1"): (NAN, 2.5, -7.0, 400.0),
    (16, "param3"): (0, 0, 0, 0),
    (16, "param4"): (NAN, 2.5, 353.0, 40.0),
    (22, "param1"): (0, 0, 0, 0),
    (22, "param2"): (0, 0, 0, 0),
    (22, "param3"): (0, 0, 0, 0),
    (21, "param1"): (0, 0, 0, 0),
    (21, "param2"): (0, 2, 65529, 400),
    (21, "param3"): (0, 0, 0, 0),
    (19, "param1"): (NAN, 2.5, -7.0, 400.0),
    (19, "param2"): (0, 1, 0, 1),
    (19, "param3"): (NAN, 2.5, -7.0, 400.0),
    (19, "param4"): (0, 1, 0, 1),
    (17, "param1"): (0, 0, 0, 0),
    (17, "param2"): (0, 0, 0, 0),
    (17, "param3"): (NAN, 2.5, -7.0, 400.0),
    (31, "param1"): (0, 1, 0, 1),
    (31, "param2"): (NAN, 2.5, -7.0, 400.0),
    (31, "param3"): (0, 0, 0, 0),
    (31, "param4"): (0, 1, 0, 1),
    (177, "param1"): (0, 2, -7, 400),
    (177, "param2"): (0, 2, 65529, 400),
    (177, "param3"): (NAN, 2.5, -7.0, 400.0),
}


@pytest.mark.parametrize(("command", "name"), list(PX4_ROWS))
def test_px4_reads_parameters_back_as_measured(command: int, name: str) -> None:
    frame = 2 if command == 177 else 3
    for value, want in zip(SAMPLES, PX4_ROWS[command, name], strict=True):
        sent = _with(command, name, value, frame)
        got = getattr(PX4.stored(sent), name)
        assert (math.isnan(got) and math.isnan(want)) or got == pytest.approx(want), (
            command,
            name,
            value,
        )
        assert PX4.same_meaning(sent, PX4.stored(sent))


def test_px4_frames_and_yaw_as_measured() -> None:
    assert PX4.stored(item(0, 16, 47.4, 8.5, frame=3)).frame == 6
    assert PX4.stored(item(0, 16, 47.4, 8.5, frame=0)).frame == 5
    assert PX4.stored(_with(16, "param4", -90.0)).param4 == pytest.approx(270.0)
    assert PX4.stored(_with(16, "param4", 370.0)).param4 == pytest.approx(9.999997, abs=1e-5)


@pytest.mark.parametrize(
    ("command", "frame", "refusal"),
    [
        (18, 3, Refusal.COMMAND),  # LOITER_TURNS
        (82, 3, Refusal.COMMAND),  # SPLINE_WAYPOINT
        (16, 10, Refusal.FRAME),
        (16, 11, Refusal.FRAME),
        (16, 1, Refusal.FRAME),  # LOCAL_NED
        (16, 99, Refusal.FRAME),
        (16, 2, Refusal.COMMAND),  # a waypoint in frame MISSION
        (177, 3, Refusal.COMMAND),  # DO_JUMP in a global frame
        (178, 6, Refusal.COMMAND),  # DO_CHANGE_SPEED
        (20, 3, Refusal.COMMAND),  # RTL
        (177, 2, None),
        (178, 2, None),
        (20, 2, None),
        (16, 0, None),
        (16, 5, None),
        (22, 3, None),
    ],
)
def test_px4_refuses_what_it_was_measured_to_refuse(
    command: int, frame: int, refusal: Refusal | None
) -> None:
    it = item(0, command, 47.4, 8.5, frame=frame)
    got = PX4.refusal(it)
    assert (got[0] if got else None) is refusal
    if refusal is not None:
        with pytest.raises(UnsupportedItem, match="item 0: PX4 refuses"):
            PX4.check([it])


def test_ardupilot_takes_what_px4_refuses_and_keeps_only_a_waypoint_delay() -> None:
    for command, frame in ((18, 3), (82, 3), (16, 10), (16, 11)):
        assert ARDUPILOT.refusal(item(0, command, 47.4, 8.5, frame=frame)) is None
    assert ARDUPILOT.refusal(item(0, 16, 47.4, 8.5, frame=99)) is not None
    wp = item(0, 16, 47.4, 8.5, frame=6).replace(param1=3.0, param2=2.0, param4=45.0)
    held = ARDUPILOT.stored(wp)
    assert (held.frame, held.param1, held.param2, held.param4) == (3, 3.0, 0.0, 0.0)
    assert ARDUPILOT.same_meaning(wp, held)


def test_a_different_position_altitude_or_reference_is_never_the_same_meaning() -> None:
    sent = item(0, 16, 47.4, 8.5, 30.0, frame=3)
    for held in (
        sent.replace(z=30.5),
        sent.replace(x=sent.x + 1),
        sent.replace(frame=5),  # AMSL, not relative
        sent.replace(command=17),
        sent.replace(param1=4.0),  # a hold time PX4 keeps
    ):
        assert not PX4.same_meaning(sent, PX4.stored(held))
        assert not ARDUPILOT.same_meaning(sent, ARDUPILOT.stored(held))


@given(st.floats(allow_nan=True, allow_infinity=False, width=32))
def test_every_param_rule_is_idempotent(value: float) -> None:
    """What the autopilot stores, uploaded again, reads back the same (a download re-uploaded
    unchanged verifies)."""
    for rule in Param:
        once = rule.apply(value)
        twice = rule.apply(once)
        assert (math.isnan(once) and math.isnan(twice)) or once == twice
