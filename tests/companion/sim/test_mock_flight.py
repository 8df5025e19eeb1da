"""The mock autopilot's flight (companion.sim.mock_flight): where a new mission leaves the
current item in flight and on the ground, DO_SET_MISSION_CURRENT, DO_JUMP loops, and a
take-off PX4 would refuse.  Driven over real UDP on loopback; the flight model is stepped by
hand."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.mission.autopilot import Autopilot
from companion.mission.flightpath import DO_JUMP, flight_order
from companion.mission.items import MissionItem
from companion.sim.mock_autopilot import MockAutopilot
from companion.sim.replay import free_udp_port as free_port
from tests.companion.missions import item
from tests.companion.sim.station import FAST, FROZEN, LAT, LON, home_item, legs, mock_and_station

pytestmark = pytest.mark.asyncio


@pytest.mark.parametrize("ardupilot", [False, True], ids=["px4", "ardupilot"])
async def test_a_takeoff_at_0_0_is_stored_but_px4_will_not_start_it(ardupilot: bool) -> None:
    mission = [item(0, 22, alt=15.0), *legs(2)[1:]]  # TAKEOFF without a position
    first = [home_item()] if ardupilot else []
    async with mock_and_station(first or None, ardupilot=ardupilot) as (mock, station):
        assert await station.upload([*first, *mission]) == mavlink.MAV_MISSION_ACCEPTED
        station.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        await station.expect("COMMAND_ACK")
        station.command(mavlink.MAV_CMD_MISSION_START)
        start = await station.expect("COMMAND_ACK")
        main, sub = (3, 0) if ardupilot else (4, 4)  # AUTO / AUTO.MISSION
        station.command(mavlink.MAV_CMD_DO_SET_MODE, 1, main, sub)
        mode = await station.expect("COMMAND_ACK")
    expected = mavlink.MAV_RESULT_ACCEPTED if ardupilot else mavlink.MAV_RESULT_DENIED
    assert (start.result, mode.result) == (expected, expected)
    assert mock.mission_running == ardupilot


# ---------------------------------------------------------------------- current item


@pytest.mark.parametrize("marked", [0, 2])
async def test_px4_restarts_an_in_flight_upload_at_the_marked_item(marked: int) -> None:
    """MAVSDK always marks one item current in an upload, and PX4 flies on from there: item 0
    sends the vehicle back to the start (the product's bug)."""
    bind, send = free_port(), free_port()
    mission = legs(5)
    mock = MockAutopilot(0, mission=mission, flight=FROZEN, bind_port=bind, send_port=send)
    async with mock:
        mock.take_off()
        mock.current = 3
        ap = await Autopilot.connect(f"udpin://127.0.0.1:{send}")
        try:
            held = await ap.download()
            assert held[3].current == 1  # the download tells where it is
            new = [it.replace(z=it.z + 10.0, current=int(i == marked)) for i, it in enumerate(held)]
            await ap.replace_mission(new, held)
        finally:
            await ap.close()
        assert mock.current == marked and mock.mission_running
        assert mock.mission[4].z == 40.0
    mock.flight = FAST  # stopped: step the model by hand
    for _ in range(400):
        mock.advance(0.1)
    assert mock.reached == list(range(marked, 5))  # from the marked item on, flown again


@pytest.mark.parametrize(("flying", "before", "after"), [(True, 3, 3), (True, 4, 2), (False, 3, 1)])
async def test_ardupilot_ignores_the_current_flag(flying: bool, before: int, after: int) -> None:
    mission = [home_item(), *legs(4)]
    async with mock_and_station(mission, ardupilot=True) as (mock, station):
        if flying:
            mock.take_off()
        mock.current = before
        new = [it.replace(current=int(i == 0)) for i, it in enumerate(mission)]
        if before == 4:
            new = new[:3]  # shorter: the index is clamped
        assert await station.upload(new) == mavlink.MAV_MISSION_ACCEPTED
        report = await station.expect("MISSION_CURRENT")
    assert mock.current == after == report.seq


@pytest.mark.parametrize("ardupilot", [False, True], ids=["px4", "ardupilot"])
async def test_do_set_mission_current(ardupilot: bool) -> None:
    """ArduPilot takes MAV_CMD_DO_SET_MISSION_CURRENT; PX4 v1.16 (measured) answers it
    UNSUPPORTED and takes only the MISSION_SET_CURRENT message."""
    mission = [home_item(), *legs(3)] if ardupilot else legs(4)
    async with mock_and_station(mission, ardupilot=ardupilot) as (mock, station):
        station.command(mavlink.MAV_CMD_DO_SET_MISSION_CURRENT, 2)
        ack = await station.expect("COMMAND_ACK")
        report = await station.expect("MISSION_CURRENT")
        assert ack.command == mavlink.MAV_CMD_DO_SET_MISSION_CURRENT
        if not ardupilot:
            assert ack.result == mavlink.MAV_RESULT_UNSUPPORTED and report.seq == 0 == mock.current
        else:
            assert ack.result == mavlink.MAV_RESULT_ACCEPTED and report.seq == 2 == mock.current
            station.command(mavlink.MAV_CMD_DO_SET_MISSION_CURRENT, 4)  # one past the end
            ack = await station.expect("COMMAND_ACK")
            assert ack.result == mavlink.MAV_RESULT_DENIED and mock.current == 2
        station.send(lambda m: m.mission_set_current_encode(1, 1, 3))  # the message works
        report = await station.expect("MISSION_CURRENT", where=lambda m: m.seq == 3)
        assert mock.current == 3


# ---------------------------------------------------------------------- DO_JUMP in flight


def jump(seq: int, target: int, repeat: int) -> MissionItem:
    return MissionItem(seq, 2, DO_JUMP, 0, 1, float(target), float(repeat), 0, 0, 0, 0, 0.0)


def flown(mock: MockAutopilot, steps: int) -> set[int]:
    """Take off and step the model by hand; the items MISSION_CURRENT named on the way."""
    mock.take_off()
    currents = {mock.current}
    for _ in range(steps):
        mock.advance(0.1)
        currents.add(mock.current)
        if not mock.mission_running:
            break
    return currents


@pytest.mark.parametrize(
    "mission",
    [
        [*legs(3), jump(3, 1, 2), item(4, 16, LAT, LON + 1e-3, 30.0)],
        # a loop inside a loop: the inner counter lives on (PX4, ArduPilot)
        [*legs(2), item(2, 16, LAT, LON + 1e-3), jump(3, 2, 1), jump(4, 1, 2), *legs(1)],
        [*legs(2), jump(2, 0, 0), item(3, 16, LAT, LON + 1e-3)],  # repeat 0: never taken
        [*legs(3), jump(3, 0, -1)],  # for ever
    ],
    ids=["repeat-2", "nested", "repeat-0", "for-ever"],
)
async def test_do_jump_loops_are_flown_as_often_as_they_say(mission: list[MissionItem]) -> None:
    mission = [it.replace(seq=i) for i, it in enumerate(mission)]
    mock = MockAutopilot(0, mission=mission, flight=FAST, bind_port=free_port())
    currents = flown(mock, 3000)
    expected = [i for i in flight_order(mission, max_jumps=None) if mission[i].command != DO_JUMP]
    forever = mission[-1].param2 == -1
    if forever:  # still flying after 3000 steps: as far as it got, many laps
        expected = expected[: max(len(mock.reached), 40)]
    assert mock.reached == expected and mock.mission_running == forever
    assert DO_JUMP not in {mission[i].command for i in currents}  # MISSION_CURRENT: flown items


# ---------------------------------------------------------------------- legacy messages
