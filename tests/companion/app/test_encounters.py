"""The pure pieces of in-flight encounters: peers, look-ahead cuts, levels, run-time estimates,
radio turns, and the planner's levels."""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
import shutil
import statistics
import tempfile
import weakref
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.app.runtime import Companion, CompanionSettings
from companion.mission.files import read_plan
from companion.mission.flightpath import flight_path
from companion.mission.ground import (
    COVER_ALL,
    along_m,
    cut_at,
    cut_behind,
    distance_m,
    near_answer,
    near_cut,
    reached_within,
)
from companion.mission.items import MissionItem
from companion.mission.levels import (
    NoClearAltitude,
    Slots,
    clear_raise,
    plan_raises,
    reach,
    reaching,
)
from companion.mission.own_flight import box_radius_m
from companion.mission.planner import OffsetSettings, plan_offsets
from companion.neighbours.beacon import Beacon
from companion.neighbours.peers import Peer, time_to_meet
from companion.neighbours.registry import NO_TAG, UNHEARD, Heard, Hearing
from companion.radio import PROFILES
from companion.radio.airtime import DutyCycle
from companion.radio.clock import Clock
from companion.radio.endpoint import LinkEndpoint
from companion.runs.edits import HOLD_RECHECK_S
from companion.runs.failsafe import (
    Action,
    FailsafeSettings,
    act_now,
    at_risk,
    run_seconds,
    too_late,
)
from companion.runs.turns import ANSWER_FULL, ANSWER_NEAR, OWN_FULL, OWN_NEAR, RadioTurns
from companion.sim.fleet import make_fleet
from companion.sim.medium import Impairments, SimMedium
from companion.sim.over_link import link_case
from companion.sim.virtual_time import run_simulated
from protocol.compact.plan import message_sizes
from protocol.geo.grid import GridKind, GridSpec
from protocol.messages import Suite
from protocol.tools.compare import Case, Party
from tests.companion.attacks.harness import FakeAutopilot
from tests.companion.missions import survey

LAT, LON = 473_977_420, 85_455_940
C_LAT, C_LON = 474_000_000, 85_450_000  # the in-flight scenarios' crossing point
SCENARIOS = Path(__file__).resolve().parents[3] / "sitl_configs" / "scenarios"
M_PER_E7_LAT = 0.0111195  # metres per degE7 of latitude


def north(metres: float) -> tuple[int, int]:
    return (LAT + round(metres / M_PER_E7_LAT), LON)


def beacon(position: tuple[int, int], slots: Slots | None = None) -> Beacon:
    return Beacon(
        position[0], position[1], 518, False, frozenset({Suite.COMPACT}), 7, 1_800_000_000, 1,
        slots or Slots.of([(517.0, 519.0)]),
    )  # fmt: skip


def alone(
    items: list[MissionItem],
    clock: Clock,
    action: Action = Action.CLIMB,
    offset: OffsetSettings | None = None,
) -> tuple[Companion, FakeAutopilot]:
    """Drone 1's companion on a radio of its own, beside a fake autopilot holding ``items``
    (its fail-safe's precaution: ``action``; its raises: ``offset``)."""
    state = Path(tempfile.mkdtemp(prefix="encounter-state-"))
    endpoint = LinkEndpoint(1, SimMedium(clock=clock).attach(1), PROFILES["us915-sf7"])
    autopilot = FakeAutopilot(items)
    c = Companion(
        CompanionSettings(
            node=1,
            autopilot_url="",
            failsafe=FailsafeSettings(action),
            offset=offset or OffsetSettings(),
        ),
        endpoint,
        autopilot,  # type: ignore[arg-type]
        make_fleet([(1, "fleet")], state)[1],
    )
    weakref.finalize(c, shutil.rmtree, state, ignore_errors=True)  # (at exit at the latest)
    c.flight.load(list(items), None)
    return c, autopilot


def test_a_run_compares_the_leg_flown_now_from_the_drone_on() -> None:
    """The leg's flown part is cut off 5 m behind the drone's foot on it (a drone off the leg
    counts from where it rejoins it); near its start, or before it, nothing is cut."""
    path = [north(0), north(300), north(600)]
    cut = cut_behind(path, north(100), 5.0)
    assert distance_m(cut[0], north(95)) < 0.05 and cut[1:] == path[1:]
    aside = cut_behind(path, (north(200)[0], north(200)[1] + 2000), 5.0)  # 15 m east of it
    assert distance_m(aside[0], north(195)) < 0.05
    assert cut_behind(path, north(3), 5.0) == path == cut_behind(path, north(-50), 5.0)
    assert distance_m(cut_behind(path, north(400), 5.0)[0], north(295)) < 0.05  # past its end


def test_cut_counts_from_the_drone() -> None:
    path = [north(0), north(300), north(600), north(900)]
    assert cut_at(path, 0) == path
    assert cut_at(path, 250) == path[:2]
    assert cut_at(path, 350) == path[:3]
    # 100 m flown on the first segment: 350 m ahead reaches 650 m, the third vertex's leg
    assert cut_at(path, 350, north(100)) == path[:3]
    assert cut_at(path, 150, north(200)) == path[:3]
    assert reached_within(path, 4, north(250), 100) == {4, 5}
    assert reached_within(path, 4, north(250), 10) == {4}


def test_near_cut_takes_what_the_padding_makes_free() -> None:
    path = [north(300 * k) for k in range(10)]  # 9 segments
    assert near_cut(path, 0) == path
    assert near_cut(path, 100) == path[:3]  # at least two segments
    assert near_cut(path, 650) == path[:5]  # three reached, padded to four
    assert near_cut(path, 1300) == path[:9]  # five reached, padded to eight
    assert near_cut(path, 5000) == path
    assert near_cut(path[:4], 100) == path[:3]  # two segments pad to two
    assert near_cut(path[:4], 650) == path[:4]  # four, but no more than there is


def test_a_near_answer_is_two_segments_and_says_how_far_they_reach() -> None:
    """Bob answers a near run with exactly his next two segments, whatever the horizon (its
    size on the air then shows nothing of his path), and their cover of the horizon asked,
    in eighths rounded down: all of it when the horizon ends within them."""
    path = [north(300 * k) for k in range(10)]  # 9 segments
    assert near_answer(path, 0) == (path, COVER_ALL)  # a full run: everything
    assert near_answer(path, 100) == (path[:3], COVER_ALL)
    assert near_answer(path, 590) == (path[:3], COVER_ALL)  # the horizon ends within them
    assert near_answer(path, 650) == (path[:3], 7)  # 600 of 650 m: 7.38 eighths
    assert near_answer(path, 1190) == (path[:3], 4)
    assert near_answer(path, 4700) == (path[:3], 1)
    assert near_answer(path, 5000) == (path[:3], 0)  # 600 m are under an eighth of it
    # from the drone, 100 m along its first segment: 500 m to the end of the second
    assert near_answer(path, 990, north(100)) == (path[:3], 4)
    assert near_answer(path[:2], 5000) == (path[:2], COVER_ALL)  # the last leg: all there is
    assert abs(along_m(path[:3], north(100)) - 500) < 0.1 and along_m(path[:1]) == 0


def east(metres: float) -> tuple[int, int]:
    return (LAT, LON + round(metres / (M_PER_E7_LAT * math.cos(math.radians(LAT / 1e7)))))


def test_precaution_covers_what_both_can_reach_before_the_result() -> None:
    """Northbound route 0-300-600-900 m, the drone at 250 m; a peer 250 m east of the 600 m
    vertex; 10 s margin.  A result in 20 s: the peer can reach 300 m (segments 1 and 2), we
    fly to 550 m (segments 0 and 1): only segment 1 needs the precaution."""
    path = [north(0), north(300), north(600), north(900)]
    peer = (north(600)[0], east(250)[1])
    settings = FailsafeSettings(margin_s=10.0, reach_margin_m=0.0)
    here = north(250)
    assert at_risk(path, 0, here, 10.0, peer, 10.0, 20.0, settings) == [1]
    # a result in 60 s: both reach everything
    assert at_risk(path, 0, here, 10.0, peer, 10.0, 60.0, settings) == [0, 1, 2]
    # a finished run decided segment 1: nothing left at risk
    assert at_risk(path, 0, here, 10.0, peer, 10.0, 20.0, settings, {1}) == []
    # further back and slow (the 5 m/s floor): we stay on segment 0, which the peer cannot
    # reach in time
    assert at_risk(path, 0, north(100), 2.0, peer, 10.0, 20.0, settings) == []
    # a peer 3 km away: nothing at risk
    assert at_risk(path, 0, here, 10.0, (LAT, east(3000)[1]), 10.0, 20.0, settings) == []
    # ... unless it was heard there 300 s ago: it may be anywhere within 3 km by now
    far = (LAT, east(3000)[1])
    assert at_risk(path, 0, here, 10.0, far, 10.0, 20.0, settings, peer_age_s=300.0) == [0, 1]


def test_precaution_enters_our_segments_by_their_windows() -> None:
    """With the schedule's windows (the earliest second we may enter each segment), those
    decide which of our segments we reach before the result, not a floor speed: the route
    and peer above, a result in 20 s (+10 s margin)."""
    path = [north(0), north(300), north(600), north(900)]
    peer = (north(600)[0], east(250)[1])
    settings = FailsafeSettings(margin_s=10.0, reach_margin_m=0.0)
    here = north(250)
    # we enter segment 1 in 5 s and segment 2 in 25 s: both before 30 s, both reachable
    assert at_risk(path, 0, here, 10.0, peer, 10.0, 20.0, settings, entered=[0, 5, 25]) == [1, 2]
    # held up: segment 2 not before 40 s -- only segment 1
    assert at_risk(path, 0, here, 10.0, peer, 10.0, 20.0, settings, entered=[0, 5, 40]) == [1]
    # a long hold before segment 1: nothing at risk
    assert at_risk(path, 0, here, 10.0, peer, 10.0, 20.0, settings, entered=[0, 50, 90]) == []
    # the peer can come within reach of segments 1 and 2 (250 m) in 25 s: a segment we have
    # left by then is not at risk
    entered = [0.0, 5.0, 25.0]
    assert at_risk(
        path, 0, here, 10.0, peer, 10.0, 20.0, settings, entered=entered, left=[5, 30, 60]
    ) == [1, 2]
    assert at_risk(
        path, 0, here, 10.0, peer, 10.0, 20.0, settings, entered=entered, left=[5, 24, 60]
    ) == [2]
    # ... heard 2 s ago: it may have flown 20 m of it already
    assert at_risk(
        path, 0, here, 10.0, peer, 10.0, 20.0, settings, entered=entered, left=[5, 24, 60],
        peer_age_s=2.0,
    ) == [1, 2]  # fmt: skip


def test_speed_is_measured_between_the_beacons_positions_not_their_arrivals() -> None:
    """A beacon queued behind a run's burst is heard late: its position's own time stamp
    measures the speed (10 m/s), not the 4 s between arrivals (which would say 35 m/s)."""
    peer = Peer(2, beacon(north(1000)), heard_at=0.0)
    peer.heard(beacon(north(1000)), 10.0, north(0), made_at=0.0)  # made at 0, heard at 10
    peer.heard(beacon(north(860)), 14.0, north(0), made_at=14.0)
    assert peer.speed_m_s == pytest.approx(10.0, rel=0.01)
    assert peer.range_rate == pytest.approx(-10.0, rel=0.01)
    assert peer.position_age(20.0) == pytest.approx(6.0)
    late = Peer(3, beacon(north(1000)), heard_at=0.0)
    late.heard(beacon(north(1000)), 10.0, north(0), made_at=0.0)
    late.heard(beacon(north(960)), 20.0, north(0), made_at=11.0)  # queued 9 s
    assert late.position_age(20.0) == pytest.approx(9.0)


def test_time_to_meet_worst_case_then_measured() -> None:
    peer = Peer(2, beacon(north(1000)), heard_at=0.0)
    assert time_to_meet(north(0), 0.0, peer, floor_m_s=5.0) == pytest.approx(100.0, rel=0.01)
    peer.heard(beacon(north(1000)), 5.0, north(0))  # hovering: its speed is 0 so far
    peer.heard(beacon(north(900)), 10.0, north(0))  # closing at 20 m/s: 900 m in 45 s
    assert time_to_meet(north(0), 0.0, peer, floor_m_s=5.0, now=10.0) == pytest.approx(
        45.0, rel=0.02
    )
    peer.heard(beacon(north(850)), 20.0, north(0))  # now closing at 5 m/s
    assert time_to_meet(north(0), 0.0, peer, floor_m_s=5.0, now=20.0) == pytest.approx(
        170.0, rel=0.02
    )
    peer.heard(beacon(north(1000)), 30.0, north(0))  # flying apart now
    assert time_to_meet(north(0), 0.0, peer, floor_m_s=5.0, now=30.0) == math.inf
    # a stale measurement falls back to the worst case: 1000 m at 10 m/s + the peer's speed,
    # less what the silent peer may have flown since it was last heard (30 s)
    v = max(peer.speed_m_s, 5.0)
    assert time_to_meet(north(0), 10.0, peer, floor_m_s=5.0, now=60.0) == pytest.approx(
        (1000 - 30 * v) / (10 + v), rel=0.02
    )
    peer.speed_m_s = 0.0  # last seen hovering: the floors decide
    assert time_to_meet(north(0), 10.0, peer, floor_m_s=5.0, now=60.0) == pytest.approx(
        (1000 - 150) / 15, rel=0.02
    )
    assert time_to_meet(
        north(0), 10.0, peer, floor_m_s=5.0, peer_floor_m_s=10.0, now=60.0
    ) == pytest.approx((1000 - 300) / 20, rel=0.02)
    assert time_to_meet(north(0), 10.0, peer, floor_m_s=5.0, now=500.0) == 0.0


def test_slots_are_what_a_path_occupies() -> None:
    """5 m slots of AMSL: a band touches every slot it reaches into; merged back into
    intervals; the last of 32 slots stands for everything above."""
    slots = Slots.of([(517.0, 519.0), (539.0, 541.0)])
    assert slots.intervals() == [(515.0, 520.0), (535.0, 545.0)]
    assert Slots.of([(500.0, 2000.0)]).intervals() == [(500.0, math.inf)]
    assert Slots.of([]).intervals() == []


def test_a_raise_clears_the_peers_slots_by_the_vertical_separation() -> None:
    """Same altitude (30 m over 488 m): 15 m up clears a 5 m slot by 10 m.  A peer 5 m
    higher: 20 m.  A raise never lands within the separation of a slot (the band of the
    drone 10 m higher is passed, not entered); between two slots of a peer it may stay."""
    band = (517.0, 519.0)  # 30 m above home, +-1 m
    same = Slots.of([(517.0, 519.0)])
    higher = Slots.of([(522.0, 524.0)])
    assert clear_raise(band, [same], 10.0, 10.0) == 15.0
    assert clear_raise(band, [higher], 10.0, 10.0) == 20.0
    assert clear_raise(band, [same, higher], 10.0, 10.0) == 20.0
    assert clear_raise(band, [Slots.of([(517.0, 519.0), (600.0, 610.0)])], 10.0, 10.0) == 15.0
    assert clear_raise(band, [Slots()], 10.0, 10.0) == 10.0  # nothing announced: the offset
    with pytest.raises(NoClearAltitude):
        clear_raise(band, [Slots.of([(500.0, 2000.0)])], 10.0, 10.0)


def test_a_raise_reaches_over_the_legs_that_climb_to_it_and_descend_from_it() -> None:
    """A leg is a straight 3-D line: the one before a raised run climbs, the first after it
    descends -- each spans the raise; where two raises meet, the larger (by size)."""
    assert reach({2: 15.0}) == {1: 15.0, 2: 15.0, 3: 15.0}
    assert reach({0: 10.0}) == {0: 10.0, 1: 10.0}  # (the take-off leg has none before it)
    assert reach({1: 20.0, 2: 10.0}) == {0: 20.0, 1: 20.0, 2: 20.0, 3: 10.0}
    assert reach({1: -10.0}) == {0: -10.0, 1: -10.0, 2: -10.0}  # (flying lower)
    assert reach({1: 0.0}) == {}


def test_a_raise_calls_for_a_run_only_with_the_peers_it_comes_near() -> None:
    """Planned at 517-519 m, raised 15 m: a peer at our cruise, or 40 m up, is as near or as
    far as before (no run); one 15 m up now lies within the 10 m separation of the band as
    flown, and so does one at 529 m, where the planned band's separation ends."""
    bands = {2: (517.0, 519.0)}
    reaches = {2: 15.0}
    assert reaching(bands, reaches, Slots.of([(517.0, 519.0)]), 10.0) == frozenset()
    assert reaching(bands, reaches, Slots.of([(557.0, 560.0)]), 10.0) == frozenset()
    assert reaching(bands, reaches, Slots.of([(532.0, 534.0)]), 10.0) == {(2, 15.0)}
    assert reaching(bands, reaches, Slots.of([(529.0, 529.0)]), 10.0) == {(2, 15.0)}
    # one peer's column from our cruise to far above: its upper part comes near
    assert reaching(bands, reaches, Slots.of([(517.0, 560.0)]), 10.0) == {(2, 15.0)}
    assert reaching(bands, {2: -15.0}, Slots.of([(495.0, 499.0)]), 10.0) == {(2, -15.0)}
    assert reaching(bands, {7: 15.0}, Slots.of([(532.0, 534.0)]), 10.0) == frozenset()


@settings(max_examples=300, deadline=None)
@given(
    low=st.integers(300, 700),
    width=st.integers(0, 30),
    extra=st.integers(-60, 60).filter(bool),
    peer=st.lists(st.tuples(st.integers(250, 800), st.integers(0, 40)), min_size=1, max_size=3),
    vertical=st.integers(5, 30),
)
def test_reaching_never_misses_an_altitude_the_raise_brings_near(
    low: int, width: int, extra: int, peer: list[tuple[int, int]], vertical: int
) -> None:
    """Against every altitude a peer's slots hold (0.5 m steps): one that is within the
    separation of the band as flown and was not of the planned band makes the raise count
    for that peer (a run must see it); a raise that counts has such an altitude, to the
    boundary."""
    band = (float(low), float(low + width))
    flown = (min(band[0], band[0] + extra), max(band[1], band[1] + extra))
    slots = Slots.of([(float(a), float(a + h)) for a, h in peer])

    def gap(alt: float, span: tuple[float, float]) -> float:
        return max(span[0] - alt, alt - span[1], 0.0)

    altitudes = [
        bottom + 0.5 * i
        for bottom, top in slots.intervals()
        for i in range(int((min(top, 1000.0) - bottom) * 2) + 1)
    ]
    found = reaching({0: band}, {0: float(extra)}, slots, float(vertical))
    if any(gap(a, flown) < vertical <= gap(a, band) for a in altitudes):
        assert found == {(0, float(extra))}
    if found:
        assert any(gap(a, flown) <= vertical <= gap(a, band) for a in altitudes)


def test_precautions_take_raises_like_conflicts() -> None:
    """Peer 2 flies 15 m up too (for a third drone): a precaution for 2 clears both of its
    slots (530-535 m: 30 m up, 547 m), as a conflict with 2 would, and merges with the
    conflicts found (peer 3 announces nothing: the offset)."""
    bands = {k: (517.0, 519.0) for k in range(4)}
    two = Slots.of([(517.0, 519.0), (532.0, 534.0)])
    assert plan_raises({}, {2: {1, 2}}, {2: two}, bands, 10.0, 10.0) == ({1: 30.0, 2: 30.0}, [])
    assert plan_raises({3: {0}}, {2: {1}}, {2: two}, bands, 10.0, 10.0) == ({0: 10.0, 1: 30.0}, [])
    assert plan_raises({2: set()}, {}, {2: two}, bands, 10.0, 10.0) == ({}, [])


def test_a_raise_stops_at_the_ceiling_and_the_others_still_fly() -> None:
    """Segment 1's conflict needs 30 m, its headroom is 20 m: it stays where it is (returned
    as unresolved, nothing raised into a peer's altitudes), segment 0's 10 m still flies --
    an edit refused whole at the ceiling left every conflict unresolved.  A raise that fits
    is the same as without a ceiling; without one, no clear altitude is still an error."""
    bands = {k: (517.0, 519.0) for k in range(2)}
    two = Slots.of([(517.0, 519.0), (532.0, 534.0)])
    found = plan_raises({3: {0}}, {2: {1}}, {2: two}, bands, 10.0, 10.0, headroom={0: 20, 1: 20})
    assert found == ({0: 10.0}, [1])
    roomy = plan_raises({3: {0}}, {2: {1}}, {2: two}, bands, 10.0, 10.0, headroom={0: 30, 1: 30})
    assert roomy == ({0: 10.0, 1: 30.0}, [])
    wall = Slots.of([(500.0, 2000.0)])
    with pytest.raises(NoClearAltitude):
        plan_raises({2: {0}}, {}, {2: wall}, bands, 10.0, 10.0)
    assert plan_raises({2: {0}}, {}, {2: wall}, bands, 10.0, 10.0, headroom={0: 100}) == ({}, [0])


def test_planner_raises() -> None:
    """Raises in metres per segment; an item shared by two raised segments takes the
    larger."""
    items = survey(6)
    path = flight_path(items, None)
    one = plan_offsets(items, {1: 10.0}, path=path)
    two = plan_offsets(items, {1: 20.0, 2: 10.0}, path=path)
    deltas_one = [b.z - a.z for a, b in zip(items, one, strict=True)]
    deltas_two = [b.z - a.z for a, b in zip(items, two, strict=True)]
    assert sorted(set(deltas_one)) == [0.0, 10.0]
    assert sorted(set(deltas_two)) == [0.0, 10.0, 20.0]  # the shared vertex takes the higher


def test_box_radius_doubles_until_the_path_fits() -> None:
    assert box_radius_m([north(100)], north(0), 500.0) == 500.0
    assert box_radius_m([north(800)], north(0), 500.0) == 1000.0
    assert box_radius_m([north(3000)], north(0), 500.0) == 4000.0


def test_estimate_matches_the_simulated_radio() -> None:
    """The fail-safe's estimate of a run against the link's own accounting (virtual time):
    within 20 % of the median of nine runs at 10 % loss (measured: 12.05 s against medians
    of 12.0 and 12.3 s, single runs 9.7-20.9 s); without the loss model's ACK round trips
    and retransmission timers it said 9.5 s."""
    grid = GridSpec(GridKind.PLANE, 2000)
    case = Case.of(((0, 0), (500, 20), (900, -40)), ((400, -300), (420, 300), (800, 600)), grid)
    party = Party.generate(Suite.COMPACT)
    for profile in ("us915-sf7", "eu868-sf7"):
        measured = [
            link_case(case, party, PROFILES[profile], Impairments(loss=0.1), seed)[
                "wall_s_simulated"
            ]
            for seed in range(1, 10)
        ]
        estimate = run_seconds(message_sizes(2, 2, grid), PROFILES[profile], loss=0.1)
        median = statistics.median(measured)
        assert 0.8 * median < estimate < 1.2 * median, (estimate, measured)


def test_estimate_counts_the_duty_cycle() -> None:
    profile = PROFILES["eu868-sf7"]
    sizes = [(True, 5000), (False, 5000)]
    fresh = DutyCycle(profile.budget_s, profile.duty_window_s, 0.1)
    spent = DutyCycle(profile.budget_s, profile.duty_window_s, 0.1)
    spent.record(0.0, 30.0)  # most of the hour's 36 s already used
    quick = run_seconds(sizes, profile, loss=0.1, duty=fresh, now=10.0)
    slow = run_seconds(sizes, profile, loss=0.1, duty=spent, now=10.0)
    assert quick < 60 and slow > 3000  # the budget returns only as the hour rolls on
    settings = FailsafeSettings()
    assert too_late(slow, 600.0, settings) and not too_late(quick, 600.0, settings)
    # A share that fits only if few frames are lost: a wait that may not come (the watch
    # of a run under way counts it when it comes), one that must.
    edge = DutyCycle(profile.budget_s, profile.duty_window_s, 0.1)
    edge.record(0.0, 32.4 - 9.0)  # 9 s left: 5000 B need 8.5 s lossless, 9.4 s at 10 % loss
    assert run_seconds(sizes, profile, loss=0.1, duty=edge, now=10.0) > 3000
    assert run_seconds(sizes, profile, loss=0.1, duty=edge, now=10.0, stall_loss=0.0) < 60
    assert run_seconds(sizes, profile, loss=0.1, duty=spent, now=10.0, stall_loss=0.0) > 3000


def test_radio_turns_by_priority() -> None:
    async def main() -> list[int]:
        radio = RadioTurns()
        order: list[int] = []

        async def use(priority: int, hold: float) -> None:
            async with radio.turn(priority):
                order.append(priority)
                await asyncio.sleep(hold)

        first = asyncio.create_task(use(OWN_FULL, 0.05))
        await asyncio.sleep(0.01)
        waiting = [asyncio.create_task(use(p, 0.0)) for p in (OWN_FULL, ANSWER_FULL, OWN_NEAR)]
        await asyncio.sleep(0.001)
        waiting.append(asyncio.create_task(use(ANSWER_NEAR, 0.0)))
        await asyncio.gather(first, *waiting)
        assert not radio.taken
        return order

    assert asyncio.run(main()) == [OWN_FULL, ANSWER_NEAR, ANSWER_FULL, OWN_NEAR, OWN_FULL]


def test_profiles() -> None:
    g3 = PROFILES["eu868-g3-sf7"]
    assert g3.duty_cycle == 0.10 and g3.budget_s == pytest.approx(360.0)
    assert distance_m(north(0), north(1000)) == pytest.approx(1000.0, rel=0.001)


def _guarded(
    busy_s: float, raised: bool = False, south_m: float = 400.0, action: Action = Action.CLIMB
) -> tuple[Companion, FakeAutopilot]:
    """Drone 1 flies east towards the crossing at 0 m (425 m ahead); peer 2, ``south_m``
    south of it, waits for its turn while the radio is busy with a run with peer 3 for ``busy_s``;
    ``raised``: a run already found the crossing leg (segment 1) in conflict with 2 and the
    drone flies it 15 m up.  Five seconds of the fail-safe's guard."""
    items, _ = read_plan(SCENARIOS / "inflight_east.plan")  # -600, -250, 250, 600 m east

    async def main() -> tuple[Companion, FakeAutopilot]:
        clock = Clock()
        c, autopilot = alone(items, clock, action)
        c.vehicle.relative_alt, c.vehicle.current_item, c.vehicle.speed_m_s = (
            30.0,
            2,
            10.0,
        )  # airborne, segment 0
        (lat, west), (_, east_) = c.flight.path.points[:2]  # -600 and -250 m: half-way, flying east
        c.vehicle.position = (lat, (west + east_) // 2, 518.0)
        south = (C_LAT - round(south_m / M_PER_E7_LAT), C_LON)
        c.neighbourhood.peers[2] = Peer(
            2, beacon(south), heard_at=clock.now(), conflicts={1} if raised else set()
        )
        if raised:
            c.flight.raises = {1: 15.0}
        c.guard.running = (3, clock.now() + busy_s)
        guard = asyncio.create_task(c.guard.guard())
        await clock.sleep(5.0)
        guard.cancel()
        return c, autopilot

    return run_simulated(main())


@pytest.mark.parametrize(("busy_s", "south_m"), [(0.0, 800.0), (100.0, 800.0), (100.0, 400.0)])
def test_guard_acts_for_a_peer_waiting_behind_another_run(busy_s: float, south_m: float) -> None:
    """Idle (:func:`_guarded`), a first run with a peer 800 m away could still end in time:
    nothing to do.  Busy for 100 s, even the smallest run with it would be late -- but it
    cannot be here sooner than 40 s, beyond the lead and margin (30 s): the guard waits (the
    run may yet end in time, the peer may never come closer).  A peer 400 m away could be
    here in 22 s: the guard climbs over the crossing leg for 2 without waiting for a run,
    and says so (``waiting``)."""
    companion, autopilot = _guarded(busy_s, south_m=south_m)
    actions = [e for e in companion.events if e.kind == "precautionary"]
    if not busy_s or south_m > 500:
        assert not actions and not autopilot.uploads
        return
    (event,) = actions
    assert event.detail["waiting"] and event.detail["peer"] == 2
    assert 1 in event.detail["segments"]  # the leg over the crossing
    assert companion.flight.raises.get(1, 0) >= 10.0 and autopilot.uploads  # climbed clear of it


def test_a_hold_stops_short_of_everything_the_peer_can_reach() -> None:
    """The peer 400 m away (:func:`_guarded`) cannot reach the leg we fly now before the
    schedule has us leave it: a climb covers the legs from the next on.  A hold stops at the
    end of this leg -- the start of the next, within the peer's reach -- so it must begin on
    this one (a real-time replay under load held at the crossing's vertex and came 2 m from
    its peer)."""
    climbed, _ = _guarded(100.0, action=Action.CLIMB)
    held, _ = _guarded(100.0, action=Action.HOLD)
    (climb,) = [e.detail for e in climbed.events if e.kind == "precautionary"]
    (hold,) = [e.detail for e in held.events if e.kind == "precautionary"]
    assert climb["segments"][0] == 1 and hold["segments"] == [0, *climb["segments"]]
    assert hold["action"] == "hold" and held.edits.holding == {2}


@pytest.mark.parametrize("max_levels", [2, None])
def test_a_conflict_no_raise_within_the_levels_clears_is_held_for(max_levels: int | None) -> None:
    """Peer 2 announces our altitude and 10-30 m above it: clearing it on the crossing leg
    (segment 1) takes 45 m.  Without a limit the drone climbs that; with two levels (20 m)
    it holds before the leg instead, asks the peer again HOLD_RECHECK_S after a result that
    still flags it, and flies on once a comparison clears the leg (the peer passed)."""
    items, _ = read_plan(SCENARIOS / "inflight_east.plan")

    async def main() -> tuple[Companion, FakeAutopilot, list[object]]:
        clock = Clock()
        c, autopilot = alone(items, clock, offset=OffsetSettings(max_levels=max_levels))
        await c._tasks.open()  # the hold's task
        c.vehicle.relative_alt, c.vehicle.current_item, c.vehicle.speed_m_s = 30.0, 2, 10.0
        c.vehicle.position = (*c.flight.path.points[1], 518.0)
        stacked = Slots.of([(517.0, 519.0), (527.0, 547.0)])
        peer = Peer(2, beacon((C_LAT, C_LON), stacked), heard_at=0.0, conflicts={1})
        c.neighbourhood.peers[2] = peer
        await c.edits.replan("a conflict on the crossing leg")
        seen: list[object] = [dict(c.flight.raises), dict(c.edits.time_holds)]
        c.vehicle.current_item = max(c.flight.path.vertices[2].items)  # on the leg: hold
        await clock.sleep(1.0)
        c.vehicle.held = True
        peer.recheck_at = math.inf
        await c.edits.replan("the result of a run still flags it")
        seen += [autopilot.pauses, peer.recheck_at - clock.now()]
        peer.conflicts = set()
        await c.edits.replan("a run cleared the leg")
        seen += [autopilot.resumes, dict(c.edits.time_holds)]
        await c._tasks.close()
        return c, autopilot, seen

    _, _, seen = run_simulated(main())
    if max_levels is None:
        assert seen[:2] == [{1: 45.0}, {}] and seen[2] == 0  # climbed, never held
        return
    raises, holds, pauses, recheck, resumes, after = seen
    assert raises == {} and holds == {2: {1}}  # no climb past two levels: a hold
    assert pauses == 1 and recheck == pytest.approx(HOLD_RECHECK_S)
    assert resumes == 1 and after == {}


def test_guard_leaves_a_leg_already_raised_for_the_peer() -> None:
    """The same busy radio, but the drone already flies the crossing leg raised for peer 2
    (a retime made them compare again): no precaution climbs it again -- the raise stands
    until the new result."""
    companion, _ = _guarded(100.0, raised=True)
    actions = [e for e in companion.events if e.kind == "precautionary"]
    assert all(1 not in e.detail["segments"] for e in actions)


def test_a_neighbour_that_has_our_key_gets_a_beacon_not_a_signed_one() -> None:
    """A neighbour whose beacon lacks a tag for us after it tagged us before has only not
    heard us lately: a beacon of ours at once, tagged -- not a signed one (138 bytes; 38 %
    of busy_ten's beacons were); one that lacks our key gets a signed one."""
    items, _ = read_plan(SCENARIOS / "inflight_east.plan")

    async def main() -> tuple[tuple[bool, bool], tuple[bool, bool]]:
        c, _ = alone(items, Clock())
        sender = c.sender
        sender._sign_next = False
        c.neighbourhood.heard(Hearing(Heard.UNKNOWN, 7, reason=UNHEARD))
        lately = (sender._now.is_set(), sender._sign_next)
        sender._now.clear()
        c.neighbourhood.heard(Hearing(Heard.UNKNOWN, 8, reason=NO_TAG))
        return lately, (sender._now.is_set(), sender._sign_next)

    lately, lacking = run_simulated(main())
    assert lately == (True, False)  # a beacon now, not signed
    assert lacking == (True, True)  # a signed one


def test_asking_an_unchecked_drone_backs_off_to_30_seconds_at_most() -> None:
    """A drone whose beacons we cannot check yet: asked at once, then less and less often
    -- but never more than 30 s apart on US915, so a few lost exchanges at
    30 % loss cost seconds, not minutes (it backed off to 5 minutes before)."""
    items, _ = read_plan(SCENARIOS / "inflight_east.plan")

    async def main() -> list[float]:
        clock = Clock()
        c, _ = alone(items, clock)
        asks = []
        for _ in range(400):
            if c.neighbourhood.may_ask(9):
                asks.append(clock.now())
            await clock.sleep(1.0)
        return asks

    asks = run_simulated(main())
    gaps = [b - a for a, b in itertools.pairwise(asks)]
    assert asks[0] == 0.0 and gaps[:3] == sorted(gaps[:3])  # at once, then less often
    assert max(gaps) <= 30.0 + 1.0 and len(asks) >= 14


def test_edit_is_built_on_the_held_mission_and_keeps_the_current_item() -> None:
    """In flight on item 2, an edit keeps item 2 current (PX4 restarts a mission at the item
    an upload marks current) and is built on what the vehicle holds (PX4 reads frame 3 back
    as 6 and zeroes parameters): only the altitudes of the flagged legs change; a vehicle
    whose mission changed under us is not edited."""
    from companion.mission.personalities import PX4

    items = [it.replace(frame=3) for it in survey(6)]
    held = [PX4.stored(it) for it in items]

    async def main(vehicle: list[MissionItem]) -> tuple[Companion, FakeAutopilot]:
        c, autopilot = alone(vehicle, Clock())
        c.flight.load(list(items), None)
        c.vehicle.relative_alt, c.vehicle.current_item = 30.0, 2
        c.edits.precaution[2] = {2}
        await c.edits.replan("test")
        return c, autopilot

    _, autopilot = run_simulated(main(held))
    (new,) = autopilot.uploads
    assert [it.current for it in new] == [0, 0, 1, 0, 0, 0]
    assert [it.frame for it in new] == [h.frame for h in held]  # the vehicle's own items
    assert [b.z - a.z for a, b in zip(items, new, strict=True)] == [0, 0, 10, 10, 0, 0]
    moved = run_simulated(main([h.replace(x=h.x + 100) for h in held]))[0]
    assert [e.kind for e in moved.events][-1] == "upload_failed"


def test_a_failed_task_is_logged_and_recorded(caplog: pytest.LogCaptureFixture) -> None:
    """A spawned task that raises is not lost: its traceback is logged and the companion
    records ``task_failed`` (a replay with one fails) -- and it ends neither the companion's
    task group nor its other tasks; a stop ends them all."""

    async def main() -> tuple[Companion, bool, bool, bool]:
        c, _ = alone(survey(4), Clock(1.0))
        await c.endpoint.start()
        await c.start_radio()

        async def broken() -> None:
            raise RuntimeError("boom")

        async def steady() -> None:
            await asyncio.sleep(3600)

        other = c.spawn(steady(), "steady")
        failed = c.spawn(broken(), "broken")
        await asyncio.sleep(0.01)
        alive = c.running and not other.done() and failed.done()
        await c.stop()
        return c, alive, other.cancelled(), c.running

    with caplog.at_level(logging.ERROR, logger="companion"):
        c, alive, cancelled, running = asyncio.run(main())
    (event,) = [e for e in c.events if e.kind == "task_failed"]
    assert "boom" in event.detail["error"] and event.detail["task"] == "broken"
    assert any(r.exc_info and "boom" in str(r.exc_info[1]) for r in caplog.records)
    assert alive  # the group and the other task went on
    assert cancelled and not running  # stopped: every task of the group ended


def test_a_late_result_is_acted_on_at_the_last_moment() -> None:
    """The precaution for a result that comes too late is due only once the peer could be
    here at the earliest (flying straight at us) within the lead and the margin (20 + 10 s):
    a run may still end meanwhile, and a peer that never comes closer never gets that close.
    The measured closing rate decides only whether the result is late.  With an infinite
    lead it is due as soon as the result is known late (:func:`too_late`)."""
    settings = FailsafeSettings(margin_s=10.0, lead_s=20.0)
    assert not act_now(5.0, 40.0, 40.0, settings)  # in time
    assert too_late(100.0, 40.0, settings) and not act_now(100.0, 40.0, 40.0, settings)
    assert act_now(100.0, 40.0, 30.0, settings)  # the last moment (by the earliest)
    assert not act_now(100.0, 200.0, 200.0, settings)  # (a peer that never comes closer)
    assert act_now(12.0, 21.0, 21.0, settings) and not act_now(12.0, 23.0, 21.0, settings)
    eager = FailsafeSettings(margin_s=10.0, lead_s=math.inf)
    for needed, meet in itertools.product((5.0, 12.0, 100.0), (21.0, 30.0, 40.0, 200.0)):
        assert act_now(needed, meet, 0.0, eager) == too_late(needed, meet, eager)
