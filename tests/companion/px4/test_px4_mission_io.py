"""companion.mission.autopilot (MAVSDK, onboard link) against real PX4 v1.16 SITL vehicles (SIH).

The harness (:mod:`companion.sim.px4`, the GCS link) puts missions on the vehicle, flies it
and reads what it holds independently of the product.  PX4 reads items back as it stores
them (frame 3 as 6, yaw -90 as 270, a LOITER_TIME's NaN param4 as 0): the product must
verify an upload by what it means, not bit for bit.
"""

from __future__ import annotations

import asyncio
import itertools
import math
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager

import pytest

from companion.mission.autopilot import Autopilot, AutopilotError
from companion.mission.items import FRAMES_RELATIVE, MissionError, MissionItem
from companion.sim.px4 import HOME, MissionRefused, Px4Build, Px4Vehicle
from protocol.geo.geodesy import ground_offset, moved

pytestmark = [
    pytest.mark.asyncio,
    pytest.mark.px4,
    pytest.mark.slow,
    pytest.mark.xdist_group("realtime"),
]

SPEED = 10.0  # PX4_SIM_SPEED_FACTOR: lock-step, about 9x real time measured on 2 cores
SETTLE_S = 0.3  # after a harness upload: a read-back at once may return the previous mission
NAN = math.nan
TAKEOFF, WAYPOINT, LOITER_TIME, LAND, LOITER_TURNS = 22, 16, 19, 21, 18


def at(north_m: float, east_m: float) -> tuple[int, int]:
    """degE7 of the point (north, east) metres from HOME."""
    lat, lon = moved(HOME[0], HOME[1], north_m, east_m)
    return round(lat * 1e7), round(lon * 1e7)


def nav(
    seq: int, command: int, where: tuple[int, int], z: float, p1: float = 0.0, p4: float = NAN
) -> MissionItem:
    """A NAV item in frame 3 (GLOBAL_RELATIVE_ALT) as a .plan file gives it."""
    return MissionItem(seq, 3, command, int(seq == 0), 1, p1, 0.0, 0.0, p4, *where, z)


def plan_mission() -> list[MissionItem]:
    """Take-off, three waypoints (the second with yaw -90), a 2 s loiter (NaN param4), land."""
    return [
        nav(0, TAKEOFF, at(0, 0), 15.0),
        nav(1, WAYPOINT, at(60, 0), 20.0),
        nav(2, WAYPOINT, at(60, 60), 20.0, p4=-90.0),
        nav(3, WAYPOINT, at(0, 60), 25.0),
        nav(4, LOITER_TIME, at(0, 30), 25.0, p1=2.0),
        nav(5, LAND, at(0, 0), 0.0),
    ]


def flight_mission() -> list[MissionItem]:
    """A short climb and first leg, then a long leg straight away from home."""
    return [
        nav(0, TAKEOFF, at(0, 0), 10.0),
        nav(1, WAYPOINT, at(60, 0), 15.0),
        nav(2, WAYPOINT, at(560, 0), 15.0),
        nav(3, LAND, at(560, 0), 0.0),
    ]


def raised(items: Sequence[MissionItem], seqs: Sequence[int], by_m: float) -> list[MissionItem]:
    return [it.replace(z=it.z + by_m) if it.seq in seqs else it for it in items]


def assert_same_places(held: Sequence[MissionItem], sent: Sequence[MissionItem]) -> None:
    """Same commands, positions and altitudes, relative altitude frames."""
    assert [it.command for it in held] == [it.command for it in sent]
    assert [(it.x, it.y) for it in held] == [(it.x, it.y) for it in sent]
    assert [it.z for it in held] == pytest.approx([it.z for it in sent], abs=1e-3)
    assert all(it.frame in FRAMES_RELATIVE for it in held)


def metres(position: tuple[float, float, float] | None, item: MissionItem) -> float:
    assert position is not None
    north, east = ground_offset(position[0], position[1], item.x / 1e7, item.y / 1e7)
    return math.hypot(north, east)


@asynccontextmanager
async def vehicle_with(
    build: Px4Build, mission: Sequence[MissionItem]
) -> AsyncIterator[tuple[Px4Vehicle, Autopilot]]:
    """A fresh SITL vehicle holding ``mission``, and the product connected to it."""
    async with Px4Vehicle(build, speed_factor=SPEED) as vehicle:
        await vehicle.upload_mission(mission)
        await asyncio.sleep(SETTLE_S)
        autopilot = await Autopilot.connect(vehicle.api_url)
        try:
            yield vehicle, autopilot
        finally:
            await autopilot.close()


async def test_download_holds_what_was_uploaded(px4_build: Px4Build) -> None:
    plan = plan_mission()
    async with vehicle_with(px4_build, plan) as (_, autopilot):
        held = await autopilot.download()
    assert_same_places(held, plan)
    assert held[2].param4 % 360 == pytest.approx(270.0)  # yaw -90 reads back wrapped


async def test_edit_of_the_download_is_verified(px4_build: Px4Build) -> None:
    async with vehicle_with(px4_build, plan_mission()) as (vehicle, autopilot):
        original = await autopilot.download()
        new = raised(original, (1, 2), 10.0)
        await autopilot.replace_mission(new, original)
        await asyncio.sleep(SETTLE_S)
        held = await vehicle.download_mission()
    assert_same_places(held, new)
    assert [it.z for it in held][1:3] == [30.0, 30.0]


async def test_edit_of_the_file_items_is_verified_by_meaning(px4_build: Px4Build) -> None:
    """The items as the .plan gives them (frame 3, yaw -90, NaN) read back as PX4 stores them
    (frame 6, yaw 270, 0): the same mission, so the edit must not be rolled back."""
    plan = plan_mission()
    async with vehicle_with(px4_build, plan) as (vehicle, autopilot):
        original = await autopilot.download()
        new = raised(plan, (1, 2), 10.0)
        await autopilot.replace_mission(new, original)
        await asyncio.sleep(SETTLE_S)
        held = await vehicle.download_mission()
    assert_same_places(held, new)


async def test_px4_refuses_loiter_turns_and_keeps_its_mission(px4_build: Px4Build) -> None:
    """PX4 itself: the whole upload is refused (UNSUPPORTED), the old mission stays."""
    plan = plan_mission()
    bad = [*plan[:3], plan[3].replace(command=LOITER_TURNS, param1=2.0), *plan[4:]]
    async with Px4Vehicle(px4_build, speed_factor=SPEED) as vehicle:
        await vehicle.upload_mission(plan)
        with pytest.raises(MissionRefused) as refused:
            await vehicle.upload_mission(bad)
        assert refused.value.name == "MAV_MISSION_UNSUPPORTED"
        await asyncio.sleep(SETTLE_S)
        assert_same_places(await vehicle.download_mission(), plan)


async def test_refused_edit_leaves_the_old_mission(px4_build: Px4Build) -> None:
    """The product: an edit with a LOITER_TURNS is an error (refused before or by PX4), and the
    vehicle still holds the mission it had."""
    plan = plan_mission()
    async with vehicle_with(px4_build, plan) as (vehicle, autopilot):
        original = await autopilot.download()
        bad = [*original[:3], original[3].replace(command=LOITER_TURNS, param1=2.0)]
        bad += original[4:]
        with pytest.raises((AutopilotError, MissionError)):
            await autopilot.replace_mission(bad, original)
        await asyncio.sleep(SETTLE_S)
        assert_same_places(await vehicle.download_mission(), plan)
        assert_same_places(await autopilot.download(), plan)


async def test_edit_in_flight_keeps_flying_to_the_current_item(px4_build: Px4Build) -> None:
    """Mid-mission, an edit that marks the vehicle's current item as current: PX4 carries on
    to that item (no restart at item 0, no turn back towards home)."""
    mission = flight_mission()
    home = nav(0, WAYPOINT, at(0, 0), 0.0)
    async with vehicle_with(px4_build, mission) as (vehicle, autopilot):
        original = await autopilot.download()
        await vehicle.take_off()
        await vehicle.wait_until(lambda: (vehicle.mission_current or 0) >= 2, 60, "item 2")
        current = vehicle.mission_current
        assert current is not None
        target = mission[current]
        to_target, from_home = metres(vehicle.position, target), metres(vehicle.position, home)
        new = raised(original, range(current, len(original) - 1), 10.0)
        new = [it.replace(current=int(it.seq == current)) for it in new]
        seqs: list[int] = []
        watch = asyncio.create_task(_record_current(vehicle, seqs))
        try:
            await autopilot.replace_mission(new, original)
            end = vehicle.sim_time_s + 8.0
            await vehicle.wait_until(lambda: vehicle.sim_time_s >= end, 10, "8 s simulated")
        finally:
            watch.cancel()
        now = vehicle.position
        held = await vehicle.download_mission()
    went = " -> ".join(str(seq) for seq, _ in itertools.groupby(seqs))
    assert min(seqs) >= current, f"the mission restarted: MISSION_CURRENT went {went}"
    closer, away = to_target - metres(now, target), metres(now, home) - from_home
    assert closer > 30.0 and away > 30.0, f"{closer:.0f} m closer to item {current}, {away:.0f} m"
    assert [it.z for it in held] == [it.z for it in new]


async def _record_current(vehicle: Px4Vehicle, seqs: list[int]) -> None:
    while True:
        if vehicle.mission_current is not None:
            seqs.append(vehicle.mission_current)
        await asyncio.sleep(0.02)


async def test_harness_flies_a_mission_to_the_end(px4_build: Px4Build) -> None:
    """The harness itself: take-off, a waypoint, land; finished when landed and disarmed,
    with the trajectory in simulated time."""
    mission = [nav(0, TAKEOFF, at(0, 0), 5.0), nav(1, WAYPOINT, at(30, 0), 5.0)]
    mission.append(nav(2, LAND, at(30, 0), 0.0))
    async with Px4Vehicle(px4_build, speed_factor=SPEED) as vehicle:
        await vehicle.upload_mission(mission)
        await vehicle.take_off()
        await vehicle.wait_finished(60)
        assert vehicle.landed and not vehicle.armed and vehicle.has_been_armed
        track = vehicle.trajectory
    times = [t for t, *_ in track]
    assert times == sorted(times) and times[-1] - times[0] > 10.0
    top = max(alt for *_, alt in track)
    assert HOME[2] + 4.0 < top < HOME[2] + 8.0
    assert metres(track[-1][1:], mission[2]) < 3.0
