"""The mock autopilot behaves like the real ones (PX4 v1.16 SITL as measured, ArduPilot as
documented): driven with raw pymavlink over real UDP on loopback, and with MAVSDK where a
ground station would use it.  Free ports only; the flight model is stepped by hand."""

from __future__ import annotations

import asyncio
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.mission.personalities import PX4
from companion.sim.mock_autopilot import FlightModel, MockAutopilot, item_message
from companion.sim.replay import free_udp_port as free_port
from tests.companion.missions import item
from tests.companion.sim.station import LAT, LON, Station, f32, home_item, legs, mock_and_station

pytestmark = pytest.mark.asyncio


async def test_px4_reads_items_back_as_it_stores_them() -> None:
    sent = [
        item(0, 22, LAT, LON, 15.0, frame=3, param1=12.0),  # TAKEOFF: pitch dropped
        item(1, 16, LAT + 1e-3, LON, 40.0, frame=0).replace(param3=5.0, param4=370.0),
        item(2, 16, LAT + 2e-3, LON, 30.0).replace(param4=-90.0),
        item(3, 19, LAT + 3e-3, LON, 30.0, param1=5.0),  # LOITER_TIME, param4 NaN
        item(4, 21, LAT + 4e-3, LON, 0.0, frame=3, param1=8.0),  # LAND: abort alt dropped
    ]
    async with mock_and_station(legs(2)) as (mock, station):
        assert await station.upload(sent) == mavlink.MAV_MISSION_ACCEPTED
        held = await station.download()
    assert [it.frame for it in held] == [6, 5, 6, 6, 6]
    assert held[0].param1 == 0 and held[4].param1 == 0
    assert held[1].param3 == 0 and held[1].param4 == pytest.approx(10.0)
    assert held[2].param4 == pytest.approx(270.0)
    assert held[3].param4 == 0 and held[3].param1 == 5.0
    assert [(it.x, it.y, it.z) for it in held] == [(it.x, it.y, it.z) for it in sent]
    want = [PX4.stored(it).replace(current=0) for it in sent]
    assert all(a.same_as(b) for a, b in zip(mock.mission, want, strict=True))


async def test_ardupilot_stores_its_frames_and_reads_home_as_item_0() -> None:
    home = (47.40, 8.55, 500.0)
    sent = [
        item(0, 16, 47.0, 8.0, 1.0),  # an item 0 that is not home: ArduPilot answers home
        item(1, 16, LAT, LON, 30.0).replace(param2=3.0, param4=45.0),
        item(2, 16, LAT + 1e-3, LON, 530.0, frame=5),
        item(3, 22, LAT, LON, 20.0, frame=11).replace(param1=math.nan),
    ]
    async with mock_and_station(None, ardupilot=True, home=home) as (mock, station):
        assert await station.upload(sent) == mavlink.MAV_MISSION_ACCEPTED
        held = await station.download()
    assert held[0].replace(current=0) == home_item(home)
    assert [it.frame for it in held] == [0, 3, 0, 10]
    assert (held[1].param2, held[1].param4) == (0, 0)
    assert held[3].param1 == 0
    assert mock.uploads_accepted == 1


@pytest.mark.parametrize(
    ("ardupilot", "command", "frame", "result"),
    [
        (False, 18, 6, mavlink.MAV_MISSION_UNSUPPORTED),  # LOITER_TURNS
        (False, 82, 6, mavlink.MAV_MISSION_UNSUPPORTED),  # SPLINE_WAYPOINT
        (False, 16, 10, mavlink.MAV_MISSION_UNSUPPORTED_FRAME),  # terrain
        (False, 16, 99, mavlink.MAV_MISSION_UNSUPPORTED_FRAME),  # no MAV_FRAME at all
        (True, 16, 99, mavlink.MAV_MISSION_UNSUPPORTED_FRAME),
        (True, 18, 11, mavlink.MAV_MISSION_ACCEPTED),  # ArduPilot flies both
    ],
    ids=["px4-loiter-turns", "px4-spline", "px4-terrain", "px4-frame-99", "ap-frame-99", "ap-ok"],
)
async def test_refused_items_end_the_upload_and_keep_the_old_mission(
    ardupilot: bool, command: int, frame: int, result: int
) -> None:
    old = legs(4)
    bad = item(1, command, LAT, LON + 1e-3, 30.0, frame=frame)
    if frame == 99:
        bad = bad.replace(x=round(LAT * 1e7), y=round(LON * 1e7))
    new = [item(0, 16, LAT, LON, 50.0), bad, item(2, 16, LAT + 1e-3, LON, 50.0)]
    async with mock_and_station(old, ardupilot=ardupilot) as (mock, station):
        assert await station.upload(new) == result
        if result == mavlink.MAV_MISSION_ACCEPTED:
            assert mock.uploads_accepted == 1 and len(mock.mission) == 3
            return
        # ArduPilot refuses the offending item at once, PX4 (measured) at the end
        assert station.requested == ([0, 1] if ardupilot else [0, 1, 2])
        assert await station.silent("MISSION_REQUEST_INT", 0.6)  # the upload is over
        assert mock.mission == old and mock.uploads_accepted == 0


async def test_a_legacy_mission_item_upload_is_taken_in_degrees() -> None:
    sent = [*legs(3), item(3, 178, frame=2, param1=5.0)]
    async with mock_and_station() as (mock, station):
        assert await station.upload(sent, legacy=True) == mavlink.MAV_MISSION_ACCEPTED
    assert len(mock.mission) == 4 and mock.received.get("MISSION_ITEM") == 4
    for got, want in zip(mock.mission[:3], sent[:3], strict=True):
        assert (got.x, got.y) == (round(f32(want.x / 1e7) * 1e7), round(f32(want.y / 1e7) * 1e7))
        assert abs(got.x - want.x) <= 20 and abs(got.y - want.y) <= 20  # float32 degrees
    assert (mock.mission[3].command, mock.mission[3].x) == (178, 0)


async def test_a_legacy_request_is_answered_with_a_legacy_item() -> None:
    async with mock_and_station(legs(2)) as (mock, station):
        station.send(lambda m: m.mission_request_encode(1, 1, 1, 0))
        old = await station.expect("MISSION_ITEM", "MISSION_ITEM_INT")
        station.send(lambda m: m.mission_request_int_encode(1, 1, 1, 0))
        new = await station.expect("MISSION_ITEM", "MISSION_ITEM_INT")
    want = mock.mission[1]
    assert old.get_type() == "MISSION_ITEM" and new.get_type() == "MISSION_ITEM_INT"
    assert (old.frame, new.frame) == (3, 6)  # the legacy twin of the frame
    assert (old.x, old.y) == pytest.approx((want.x / 1e7, want.y / 1e7), abs=5e-6)
    assert (new.x, new.y, new.seq) == (want.x, want.y, 1)


# ---------------------------------------------------------------------- clearing, home


@pytest.mark.parametrize("ardupilot", [False, True], ids=["px4", "ardupilot"])
async def test_clear_all_and_empty_uploads_keep_only_ardupilots_home(ardupilot: bool) -> None:
    """CLEAR_ALL 255 clears mission, fence and rally; so does COUNT 0 the mission.  ArduPilot
    keeps its home (the constructor's, also in HOME_POSITION) as item 0."""
    home = (47.41, 8.56, 470.0)
    mission = [home_item(home), *legs(3)] if ardupilot else legs(3)
    left = [home_item(home)] if ardupilot else []
    async with mock_and_station(mission, ardupilot=ardupilot, home=home) as (mock, station):
        fence = [item(i, 5003, LAT + i * 1e-3, LON).replace(mission_type=1) for i in range(4)]
        assert await station.upload(fence, 1) == mavlink.MAV_MISSION_ACCEPTED
        assert await station.upload(legs(1), 2) == mavlink.MAV_MISSION_ACCEPTED  # rally
        station.send(lambda m: m.mission_clear_all_encode(1, 1, 255))
        ack = await station.expect("MISSION_ACK")
        assert (ack.type, ack.mission_type) == (mavlink.MAV_MISSION_ACCEPTED, 255)
        assert mock.stores[1] == mock.stores[2] == [] and mock.mission == left
        assert await station.upload(mission) == mavlink.MAV_MISSION_ACCEPTED
        assert await station.upload([]) == mavlink.MAV_MISSION_ACCEPTED
        assert await station.download() == [it.replace(current=1) for it in left]
        station.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION)
        told = await station.expect("HOME_POSITION")
    assert mock.mission == left and mock.current == 0
    assert (told.latitude, told.longitude, told.altitude) == (474100000, 85600000, 470000)


# ---------------------------------------------------------------------- links


async def test_the_gcs_link_is_off_with_explicit_ports_and_on_per_instance() -> None:
    assert MockAutopilot(0, bind_port=free_port()).gcs_bind_port == 0
    per_instance = MockAutopilot(3)  # not started: nothing bound
    assert (per_instance.bind_port, per_instance.send_port) == (14583, 14543)
    assert (per_instance.gcs_bind_port, per_instance.gcs_send_port) == (18573, 14550)
    assert MockAutopilot(3, gcs_bind_port=0).gcs_bind_port == 0


async def test_a_ground_station_does_not_take_telemetry_from_the_api_link() -> None:
    gcs_bind, gcs_send = free_port(), free_port()
    fast_telemetry = FlightModel(time_scale=0.0, rate_hz=20.0)
    links = {"gcs_bind_port": gcs_bind, "gcs_send_port": gcs_send, "flight": fast_telemetry}
    async with mock_and_station(legs(3), **links) as (mock, api):  # api: where MAVSDK listens
        gcs = await Station.open(gcs_bind, gcs_send)  # where QGroundControl listens
        intruder = await Station.open(mock.bind_port, 0, sysid=254)  # 2nd station, API link
        try:
            await api.expect("HEARTBEAT")  # sent to the API send port from the start
            api.send(lambda m: m.heartbeat_encode(18, 8, 0, 0, 0, 3))  # MAVSDK: partner 1
            await asyncio.sleep(0.05)
            await gcs.expect("GLOBAL_POSITION_INT")  # the GCS link talks from the start
            gcs.send(lambda m: m.heartbeat_encode(6, 8, 0, 0, 0, 3))
            intruder.send(lambda m: m.heartbeat_encode(6, 8, 0, 0, 0, 3))
            intruder.send(lambda m: m.mission_request_list_encode(1, 1, 0))
            await asyncio.sleep(0.1)
            api.forget()
            for name in ("GLOBAL_POSITION_INT", "HEARTBEAT", "MISSION_CURRENT"):
                await api.expect(name, timeout=2.0)  # still the API link's partner
                await gcs.expect(name, timeout=2.0)
            assert await intruder.silent("MISSION_COUNT", 0.3)  # the first partner is kept
            # a reply goes to the link the request came on
            gcs.forget()
            api.forget()
            gcs.send(lambda m: m.mission_request_list_encode(1, 1, 0))
            assert (await gcs.expect("MISSION_COUNT")).count == 3
            assert await api.silent("MISSION_COUNT", 0.3)
            # one mission store for both links: an upload on the GCS link is the API's mission
            assert await gcs.upload(legs(2)) == mavlink.MAV_MISSION_ACCEPTED
            assert len(await api.download()) == 2
            assert mock.api_link is not None and mock.api_link.partner[1] == mock.send_port
            assert mock.gcs_link is not None and mock.gcs_link.partner[1] == gcs_send
        finally:
            gcs.close()
            intruder.close()


async def test_the_newer_upload_wins_across_links() -> None:
    gcs_bind = free_port()
    async with mock_and_station(legs(1), gcs_bind_port=gcs_bind) as (mock, api):
        gcs = await Station.open(gcs_bind)
        try:
            api.send(lambda m: m.mission_count_encode(1, 1, 3, 0))
            await api.expect("MISSION_REQUEST_INT")
            assert await gcs.upload(legs(2, alt=60.0)) == mavlink.MAV_MISSION_ACCEPTED
            api.send(lambda m: item_message(m, 1, 1, legs(3)[0]))  # too late: ignored
            assert await api.silent("MISSION_REQUEST_INT", 0.4)
        finally:
            gcs.close()
    assert [it.z for it in mock.mission] == [60.0, 60.0]
