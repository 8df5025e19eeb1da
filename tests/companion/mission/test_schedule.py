"""The flown path in four dimensions (companion.mission.schedule): when the drone is at each vertex
and how high, the bands and windows a run compares, and when a drone has left its windows."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.mission.flight_model import Kinematics, fly
from companion.mission.flightpath import flight_path
from companion.mission.items import MissionItem
from companion.mission.schedule import (
    PIECE_LAG_S,
    PIECE_MIN_S,
    T_RANGE_S,
    Passage,
    Schedule,
    SeparationSettings,
    Tolerance,
    Vehicle,
    off_schedule,
    predict,
    route_volumes,
    run_volumes,
    split_long,
)
from protocol.geo.geodesy import moved
from protocol.geo.volumes import Separation
from tests.companion.missions import HOME, item

HOME_E7 = (round(HOME[0] * 1e7), round(HOME[1] * 1e7))


def east(metres: float) -> tuple[float, float]:
    return moved(HOME[0], HOME[1], 0.0, metres)


def mission(*legs: tuple[float, float], loiter_s: float = 0.0) -> list[MissionItem]:
    """Take-off to 30 m over home, then waypoints (east metres, metres above home), a
    loiter of ``loiter_s`` at the second if given, and a landing at the last point."""
    items = [item(0, 22, *HOME[:2], 30.0)]
    for i, (metres, alt) in enumerate(legs, start=1):
        command, hold = (19, loiter_s) if loiter_s and i == 2 else (16, 0.0)
        items.append(item(i, command, *east(metres), alt, param1=hold))
    items.append(item(len(items), 21, *east(legs[-1][0]), 0.0))
    return items


def ground(items: list[MissionItem], wait_s: float = math.inf) -> Schedule:
    path = flight_path(items, HOME_E7)
    vehicle = Vehicle(*HOME[:2], 0.0, 0.0, 0, True, wait_s=wait_s)
    return predict(path, items, HOME, 0, vehicle, Kinematics())


def test_from_the_ground_windows_open_as_if_it_took_off_now() -> None:
    """Before take-off every window opens as if the drone took off now; with no bound on
    when it leaves it never closes, with one (it takes off within ``wait_s``) it closes that
    much later than the flight from now would; bands span what each segment flies."""
    items = mission((300.0, 30.0), (600.0, 50.0), (900.0, 50.0))
    schedule = ground(items)
    assert not schedule.open_ended and schedule.wait_s == math.inf
    arrivals = [p.arrive for p in schedule.passages]
    assert arrivals == sorted(arrivals) and arrivals[-1] > 60.0  # 600 m at about 9.5 m/s
    tolerance = Tolerance()
    for k in range(len(schedule.passages) - 1):
        assert schedule.window(k, tolerance)[1] == math.inf
    bounded = ground(items, wait_s=120.0)
    assert bounded.passages == schedule.passages
    for k in range(len(schedule.passages) - 1):
        low, high = bounded.window(k, tolerance)
        leave = bounded.passages[k + 1].leave
        assert low == schedule.window(k, tolerance)[0]
        assert high == pytest.approx(leave + 120.0 + tolerance.late(leave))
    # the climbing leg from 30 m to 50 m: its band spans both ends and the altitude error
    assert schedule.band(1) == pytest.approx((488.0 + 30.0 - 1.0, 488.0 + 50.0 + 1.0), abs=0.2)
    # the last leg ends in the landing's column: its band reaches the ground
    assert schedule.band(2)[0] == pytest.approx(488.0 - 1.0)
    # the take-off's column is in its band (from the ground) but not in its cruise band
    assert schedule.band(0)[0] == pytest.approx(488.0 - 1.0)
    assert schedule.cruise(0)[0] > 488.0 + 25.0


def test_in_flight_windows_close_and_widen_with_time_ahead() -> None:
    """Mid-flight the prediction starts from the vehicle's state and every window closes;
    the late side is wider than the early side (a drone falls behind easily, it does not
    fly faster than commanded), and both grow with the time ahead."""
    items = mission((300.0, 30.0), (900.0, 30.0), (1500.0, 30.0))
    path = flight_path(items, HOME_E7)
    lat, lon = east(100.0)
    vehicle = Vehicle(lat, lon, 30.0, 9.45, 1, False)
    schedule = predict(path, items, HOME, path.start_at(1), vehicle, Kinematics())
    assert not schedule.open_ended
    tolerance = Tolerance(altitude_m=1.0, late_s=15.0, early_s=5.0, rate=0.1)
    first = schedule.first
    near = schedule.window(first + 1, tolerance)
    far = schedule.window(first + 2, tolerance)
    a, b = schedule.passages[1], schedule.passages[2]
    assert near == pytest.approx((a.arrive - 5.0 - 0.1 * a.arrive, b.leave + 15.0 + 0.1 * b.leave))
    assert far[1] - far[0] > near[1] - near[0]
    assert 20.0 < a.arrive < 25.0  # 200 m to the vertex at cruise speed


def test_prediction_agrees_with_the_flight_it_predicts() -> None:
    """The schedule from the ground is the flight model's own flight: each vertex is
    reached when a flight of the same mission reaches its item (to the prediction's step:
    half a second, where the flight here steps a quarter)."""
    items = mission((300.0, 40.0), (700.0, 40.0))
    _, reached = fly(items, HOME)
    schedule = ground(items)
    path = flight_path(items, HOME_E7)
    when = {r.item: r.t for r in reached}
    for k, vertex in enumerate(path.vertices[1:], start=1):
        first_item = min(vertex.items)
        assert schedule.passages[k].arrive == pytest.approx(when[first_item], abs=1.0)


def test_a_loiter_under_way_counts_down() -> None:
    """Over the loiter point for 100 s of its 300 s: the drone leaves in 200 s, not 300 s."""
    items = mission((300.0, 30.0), (600.0, 30.0), (900.0, 30.0), loiter_s=300.0)
    path = flight_path(items, HOME_E7)
    lat, lon = east(600.0)
    start = path.start_at(2)

    def leave(loitering_s: float) -> float:
        vehicle = Vehicle(lat, lon, 30.0, 0.0, 2, False, loitering_s)
        schedule = predict(path, items, HOME, start, vehicle, Kinematics())
        return schedule.passages[2 - start].leave

    assert leave(0.0) == pytest.approx(300.0, abs=2.0)
    assert leave(100.0) == pytest.approx(200.0, abs=2.0)


def test_a_short_prediction_marks_what_it_did_not_reach() -> None:
    items = mission((300.0, 30.0), (900.0, 30.0), (3000.0, 30.0))
    path = flight_path(items, HOME_E7)
    vehicle = Vehicle(*east(10.0), 30.0, 9.45, 1, False)
    schedule = predict(path, items, HOME, 0, vehicle, Kinematics(), limit_s=60.0)
    reached = [p.reached for p in schedule.passages]
    assert reached[:3] == [True, True, False] and not any(reached[3:])


def passages(*arrivals: float) -> tuple[Passage, ...]:
    return tuple(Passage(t, t, 500.0, 500.0) for t in arrivals)


@pytest.mark.parametrize(
    ("shift", "expected"),
    [
        (0.0, None),
        (8.0, None),  # 8 s late at 20 s ahead: within half of 15 + 0.1 x 20 = 8.5
        (9.0, 9.0),
        (-3.0, None),  # early: within half of 5 + 2 = 3.5
        (-4.0, -4.0),
    ],
)
def test_off_schedule_by_half_the_tolerance(shift: float, expected: float | None) -> None:
    """Predicted at t = 100 (vertices at 120, 160, 200), predicted again at t = 100 + shift
    with the same times ahead: the drone is ``shift`` seconds behind (positive) or ahead.
    The first vertex ahead is 20 s away: it decides."""
    tolerance = Tolerance(late_s=15.0, early_s=5.0, rate=0.1)
    before = Schedule(0, passages(0.0, 20.0, 60.0, 100.0), False)
    now = Schedule(0, passages(0.0, 20.0, 60.0, 100.0), False)
    drift = off_schedule(before, 100.0, now, 100.0 + shift, tolerance)
    assert drift == (None if expected is None else pytest.approx(expected))


def test_off_schedule_compares_the_same_vertices() -> None:
    """Later, on the next leg (first vertex 1): vertex 2 at 40 s from t = 120 is vertex 2
    at 60 s from t = 100 -- on time; vertices not reached in a prediction are skipped."""
    tolerance = Tolerance()
    before = Schedule(0, passages(0.0, 20.0, 60.0, 100.0), False)
    now = Schedule(1, passages(0.0, 40.0, 80.0), False)
    assert off_schedule(before, 100.0, now, 120.0, tolerance) is None
    unreached = Schedule(1, (*passages(0.0, 40.0), Passage(400.0, math.inf, 0, 0, False)), False)
    assert off_schedule(before, 100.0, unreached, 120.0, tolerance) is None
    assert off_schedule(before, 100.0, now, 160.0, tolerance) == pytest.approx(40.0)


def test_run_volumes_in_grid_cells() -> None:
    """Separations rounded up to whole cells, the horizontal one widened by the grid's own
    error (sqrt(2) cells: each vertex snapped to its cell); none at all stays none."""
    settings = SeparationSettings(horizontal_m=15.0, vertical_m=10.0)
    assert run_volumes(settings, 1000, 7).separation == Separation(17, 10)
    assert run_volumes(settings, 500, 7).separation == Separation(32, 20)
    assert run_volumes(settings, 1000, 7).epoch_s == 7
    crossing = SeparationSettings(horizontal_m=0.0, vertical_m=0.0)
    assert run_volumes(crossing, 1000, 0).separation == Separation(0, 0)


def test_route_volumes_round_outwards_after_the_epoch() -> None:
    """Bands in cells (floor / ceil), windows in whole seconds after the run's epoch (the
    schedule's zero was ``since`` seconds after it), open-ended ones to the time range."""
    closed = Schedule(
        0, (Passage(0.0, 0.0, 517.2, 517.2), Passage(30.0, 30.0, 527.9, 527.9)), False
    )
    tolerance = Tolerance(altitude_m=1.0, late_s=10.0, early_s=2.0, rate=0.0)
    bands, windows = route_volumes(closed, 0, 1, 1000, 5.5, tolerance)
    assert bands == ((516, 529),)
    assert windows == ((math.floor(-2.0 + 5.5), math.ceil(30.0 + 10.0 + 5.5)),)
    open_ended = Schedule(0, closed.passages, True)  # (held in the air)
    _, windows = route_volumes(open_ended, 0, 1, 500, 0.0, tolerance)
    assert windows == ((-2, T_RANGE_S),)
    # Alice's raises as flown: the band spans them as well, outwards only
    bands, _ = route_volumes(closed, 0, 1, 1000, 5.5, tolerance, {0: (520.0, 543.5)})
    assert bands == ((516, 544),)
    bands, _ = route_volumes(closed, 0, 1, 1000, 5.5, tolerance, {1: (400.0, 600.0)})
    assert bands == ((516, 529),)  # (another segment's)


# ---------------------------------------------------------------------------- parts of legs


def test_a_long_leg_is_cut_in_parts_with_windows_of_their_own() -> None:
    """Free slots of a run's size halve the leg flown longest while it is flown for at least
    PIECE_MIN_S: a 400 s leg in four parts of 100 s next to a 60 s leg that stays whole.
    Each part's window lies within the leg's and the parts' windows cover it; the first
    part's ends 200 s and more before the leg's does."""
    schedule = Schedule(0, passages(0.0, 400.0, 460.0), False)
    tolerance = Tolerance()
    pieces = split_long(schedule, 0, 2, 5)
    assert pieces == [(0, 0.0, 0.25), (0, 0.25, 0.5), (0, 0.5, 0.75), (0, 0.75, 1.0), (1, 0.0, 1.0)]
    low, high = schedule.window(0, tolerance)
    windows = [schedule.piece_window(k, (a, b), tolerance) for k, a, b in pieces[:4]]
    assert windows[0][0] == low and windows[-1][1] == high
    for (a0, a1), (b0, b1) in itertools.pairwise(windows):
        assert low <= a0 <= b0 and a1 <= b1 <= high and b0 <= a1  # in order, overlapping
    assert windows[0][1] <= high - 200.0
    assert split_long(schedule, 0, 2, 2) == [(0, 0.0, 1.0), (1, 0.0, 1.0)]  # no slot free
    held = Schedule(0, passages(0.0, 400.0, 460.0), True)
    assert split_long(held, 0, 2, 8) == [(0, 0.0, 1.0), (1, 0.0, 1.0)]  # when is not known


def test_a_whole_part_has_its_segment_s_window() -> None:
    """A segment not cut has the window it always had: from reaching its first vertex to
    leaving its last, a loiter's time included, widened by the tolerance."""
    schedule = Schedule(0, (Passage(0.0, 30.0, 500.0, 500.0), *passages(130.0, 250.0)), False)
    tolerance = Tolerance()
    for k in (0, 1):
        assert schedule.piece_window(k, (0.0, 1.0), tolerance) == schedule.window(k, tolerance)
    assert schedule.window(0, tolerance) == (-tolerance.early_s, 130.0 + tolerance.late(130.0))


@given(
    leave=st.floats(0.0, 100.0),
    flown=st.floats(PIECE_MIN_S, 3000.0),
    shares=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2),
    where=st.floats(0.0, 1.0),
    off=st.floats(-1.0, 1.0),
    wait=st.sampled_from([0.0, 45.0]),
)
def test_a_part_s_window_holds_every_moment_the_drone_may_fly_it(
    leave: float, flown: float, shares: list[float], where: float, off: float, wait: float
) -> None:
    """Wherever the drone is on the part -- at a time its share of the leg gives, give or
    take PIECE_LAG_S, and never outside the leg's own flight -- that moment widened by the
    tolerance lies within the part's window."""
    start, end = sorted(shares)
    a = Passage(0.0, leave, 500.0, 500.0)
    b = Passage(leave + flown, leave + flown, 500.0, 500.0)
    schedule = Schedule(0, (a, b), False, wait_s=wait)
    tolerance = Tolerance()
    low, high = schedule.piece_window(0, (start, end), tolerance)
    share = start + where * (end - start)
    linear = leave + share * flown
    t = min(max(linear + off * PIECE_LAG_S, leave), leave + flown)
    assert low <= t - tolerance.early(t) + 1e-9
    assert t + wait + tolerance.late(t) <= high + 1e-9
