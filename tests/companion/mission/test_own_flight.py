"""Our own flight as one component (companion.mission.own_flight): the mission it holds, what
is left of it, and keeping to its windows -- driven through its methods only."""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any

from companion.context import Context
from companion.events import EventKind, Payload
from companion.mission.levels import Slots
from companion.mission.own_flight import OwnFlight
from companion.mission.planner import Edit
from companion.mission.vehicle import VehicleState
from companion.radio.clock import Clock
from companion.settings import CompanionSettings
from companion.sim.virtual_time import run_simulated
from tests.companion.missions import HOME, survey


class _Record:
    def __init__(self) -> None:
        self.events: list[tuple[EventKind, Payload]] = []
        self.announced = 0

    def record(self, kind: EventKind, payload: Payload) -> None:
        self.events.append((kind, payload))

    def announce(self) -> None:
        self.announced += 1


def _never(work: Coroutine[Any, Any, None], name: str) -> asyncio.Task[None]:
    work.close()
    raise AssertionError(f"OwnFlight spawns nothing ({name})")


def _flight(n: int = 6) -> tuple[OwnFlight, _Record]:
    out = _Record()
    ctx = Context(CompanionSettings(node=1, autopilot_url=""), Clock(), out.record, _never)
    flight = OwnFlight(ctx, VehicleState(), out.announce)
    home = (round(HOME[0] * 1e7), round(HOME[1] * 1e7), 488.0)
    flight.load(survey(n), home)
    return flight, out


def test_before_take_off_the_whole_path_is_left_and_after_the_last_item_nothing() -> None:
    async def main() -> None:
        flight, _ = _flight()
        first, points = flight.remaining_path()
        assert first == 0 and points == flight.path.points and not flight.done
        v = flight.vehicle
        v.moved(HOME[0], HOME[1], 520.0, 30.0, now=1.0)  # airborne
        v.current_item = 3
        start, rest = flight.remaining_path()
        assert 0 < start and rest == flight.path.points[start:] and not flight.done
        v.moved(HOME[0], HOME[1], 488.0, 0.0, now=2.0)  # landed mid-mission: not done
        assert not flight.done
        v.current_item = len(flight.mission) - 1  # landed, the last item current
        assert len(flight.remaining_path()[1]) == 1  # the landing point: nothing to compare
        assert flight.done  # (its beacons go less often)

    run_simulated(main())


def test_a_hold_in_the_air_moves_the_windows_on_once() -> None:
    """Holding: when it flies on is unknown -- the schedule's epoch moves on (a new version,
    every peer compares again) once when the hold begins, and our beacons say so at once."""

    async def main() -> tuple[list[tuple[EventKind, Payload]], int, bool]:
        flight, out = _flight()
        v = flight.vehicle
        v.moved(HOME[0], HOME[1], 520.0, 30.0, now=0.0)
        v.current_item = 1
        flight.keep_time()  # in flight: the schedule kept from here
        before = flight.version
        v.held = True
        for _ in range(3):
            flight.keep_time()
        return out.events, out.announced, flight.version != before

    events, announced, changed = run_simulated(main())
    assert [kind for kind, _ in events] == [EventKind.RETIMED] and announced == 1 and changed


def test_progress_during_an_upload_keeps_the_old_numbering() -> None:
    """While an edit is uploaded the vehicle reports items of the new mission: the current
    item stays until the read-back is done; then it flies on from what it reported since."""

    async def main() -> tuple[int, int]:
        flight, _ = _flight()
        flight.progress(2, len(flight.mission), 1.0)
        async with flight.editing:
            flight.progress(5, len(flight.mission) + 1, 2.0)  # the new mission's numbering
            during = flight.vehicle.current_item
            new = [*flight.mission, flight.mission[-1].replace(seq=len(flight.mission))]
            edit = Edit(new, (*range(len(flight.mission)), len(flight.mission) - 1), None)
            flight.edited(new, {1: 10.0}, edit, mark=2, sent=1.5)
        return during, flight.vehicle.current_item

    during, after = run_simulated(main())
    assert during == 2 and after == 5  # reported after the upload began: taken


def test_the_size_class_counts_a_waypoint_an_edit_inserted() -> None:
    """Our size class (beacons) is the n of every full run we answer: with a waypoint an
    edit inserted, the mission the vehicle holds has a segment more than the original --
    five where four pad to four -- and the class counts it (it said 4, and a full run then
    showed listeners 8)."""
    flight, _ = _flight(6)
    assert len(flight.remaining_path()[1]) - 1 == 4 and flight.own_size() == 4
    m = flight.mission
    inserted = m[2].replace(x=m[2].x + 5000)
    new = [*m[:2], inserted, *[it.replace(seq=it.seq + 1) for it in m[2:]]]
    flight.edited(new, {}, Edit(new, (0, 1, 2, *range(2, len(m))), 2), mark=0, sent=0.0)
    assert len(flight.remaining_flown()[1]) - 1 == 5 and flight.own_size() == 8


def test_our_runs_compare_our_raises_and_count_them_for_the_peers_they_come_near() -> None:
    """Segment 2 raised 15 m: a run compares it, and the legs that climb to it and descend
    from it, from the planned band up to the raise; the raise is news to a peer cruising
    15 m above our plan (it comes near), not to one at our cruise or far above."""
    flight, _ = _flight()
    bands = flight.planned_bands()
    assert flight.reaches() == {} and flight.raises_near(Slots.of([bands[2]])) == frozenset()
    flight.raises = {2: 15.0}
    reaches = flight.reaches()
    assert sorted(reaches) == [1, 2, 3]
    for k, (low, high) in reaches.items():
        assert (low, high) == (bands[k][0], bands[k][1] + 15)
    low, high = bands[2]
    assert flight.raises_near(Slots.of([(low, high)])) == frozenset()  # our cruise
    assert flight.raises_near(Slots.of([(low + 80, high + 80)])) == frozenset()
    above = flight.raises_near(Slots.of([(low + 15, high + 15)]))
    assert (2, 15.0) in above and all(extra == 15.0 for _, extra in above)
