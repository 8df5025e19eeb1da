"""MAVSDK 4.1 (the real library) against the mock autopilot over real UDP on loopback.

Every test ends with the vehicle holding either the new mission or the old one, never a mix.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Protocol

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.mission.autopilot import Autopilot, AutopilotError, RolledBack, Timeouts
from companion.mission.flight_model import Kinematics
from companion.mission.flightpath import flight_path
from companion.mission.items import MissionItem, normalise
from companion.mission.personalities import personality
from companion.mission.planner import plan_offsets
from companion.sim.mock_autopilot import Faults, FlightModel, MockAutopilot, item_message
from companion.sim.replay import free_udp_port
from tests.companion.missions import HOME, item, survey

pytestmark = pytest.mark.asyncio


@asynccontextmanager
async def vehicle(
    mission: list[MissionItem],
    *,
    ardupilot: bool = False,
    faults: Faults | None = None,
    flight: FlightModel | None = None,
    timeouts: Timeouts | None = None,
) -> AsyncIterator[tuple[MockAutopilot, Autopilot]]:
    bind, send = free_udp_port(), free_udp_port()
    mock = MockAutopilot(
        0,
        mission=mission,
        ardupilot=ardupilot,
        faults=faults,
        flight=flight,
        bind_port=bind,
        send_port=send,
    )
    async with mock:
        ap = await Autopilot.connect(f"udpin://127.0.0.1:{send}", timeouts or Timeouts())
        try:
            yield mock, ap
        finally:
            await ap.close()


def _same(a: list[MissionItem], b: list[MissionItem]) -> bool:
    return len(a) == len(b) and all(
        x.replace(current=0).same_as(y.replace(current=0)) for x, y in zip(a, b, strict=True)
    )


def _means(ardupilot: bool, sent: list[MissionItem], held: list[MissionItem]) -> bool:
    """``held`` is what the autopilot makes of ``sent`` (its frames, parameters, yaw)."""
    same = personality(ardupilot).same_meaning
    return len(sent) == len(held) and all(map(same, sent, held))


def _edit(items: list[MissionItem], ardupilot: bool) -> list[MissionItem]:
    path = flight_path(items, None, ardupilot=ardupilot)
    out = plan_offsets(items, {0} if path.segments else set(), path=path)
    return [it.replace(current=int(i == 0)) for i, it in enumerate(out)]


def _px4(n: int) -> list[MissionItem]:
    return survey(n) if n > 1 else [item(0, 16, 47.398, 8.546)]


def _ardupilot(n: int) -> list[MissionItem]:
    home = item(0, 16, HOME[0], HOME[1], HOME[2], frame=0)
    return normalise([home, *survey(n - 1)])


@pytest.mark.parametrize("ardupilot", [False, True], ids=["px4", "ardupilot"])
@pytest.mark.parametrize("size", [1, 7, 120, 500])
async def test_download_edit_upload_verify(ardupilot: bool, size: int) -> None:
    original = (_ardupilot if ardupilot else _px4)(max(size, 2 if ardupilot else 1))
    async with vehicle(original, ardupilot=ardupilot) as (mock, ap):
        held = await ap.download()
        assert _means(ardupilot, original, held)
        new = _edit(held, ardupilot)
        await ap.replace_mission(new, held)
        assert _same(mock.mission, [mock.personality.stored(it) for it in new])
        if ardupilot:
            assert mock.personality.same_meaning(original[0], mock.mission[0])  # home untouched


@pytest.mark.parametrize(
    "faults",
    [Faults(drop_every=3), Faults(latency_s=0.1), Faults(drop_every=5, latency_s=0.03)],
    ids=["drop-every-3rd", "latency", "both"],
)
async def test_transfers_survive_dropped_replies_and_latency(faults: Faults) -> None:
    original = survey(12)
    async with vehicle(original, faults=faults) as (mock, ap):
        held = await ap.download()
        new = _edit(held, False)
        await ap.replace_mission(new, held)
        assert _same(mock.mission, new)


async def test_a_garbled_write_is_rolled_back() -> None:
    original = survey(12)
    async with vehicle(original, faults=Faults(garble_uploads=1)) as (mock, ap):
        held = await ap.download()
        with pytest.raises(RolledBack, match="read-back differs"):
            await ap.replace_mission(_edit(held, False), held)
        assert _same(mock.mission, original)


@pytest.mark.parametrize(
    "faults",
    [
        Faults(reject_upload=mavlink.MAV_MISSION_NO_SPACE),
        Faults(ignore=frozenset({"MISSION_COUNT"})),
    ],
    ids=["rejected", "ignored"],
)
async def test_a_refused_upload_leaves_the_old_mission(faults: Faults) -> None:
    original = survey(9)
    timeouts = Timeouts(transfer_s=8.0, retries=0)
    async with vehicle(original, faults=faults, timeouts=timeouts) as (mock, ap):
        held = await ap.download()
        with pytest.raises(AutopilotError, match="upload failed"):
            await ap.replace_mission(_edit(held, False), held)
        assert _same(mock.mission, original) and mock.uploads_accepted == 0


async def test_a_vanished_autopilot_is_reported_not_waited_on() -> None:
    timeouts = Timeouts(transfer_s=5.0, retries=0)
    async with vehicle(survey(5), faults=Faults(vanish_after_s=4.0), timeouts=timeouts) as (_, ap):
        await ap.download()  # alive ...
        await asyncio.sleep(4.2)  # ... then gone
        start = time.monotonic()
        with pytest.raises(AutopilotError, match="download failed"):
            await ap.download()
        assert time.monotonic() - start < 10


async def test_no_autopilot_at_all() -> None:
    start = time.monotonic()
    with pytest.raises(AutopilotError, match="no autopilot heard"):
        await Autopilot.connect(f"udpin://127.0.0.1:{free_udp_port()}", Timeouts(connect_s=1.0))
    assert time.monotonic() - start < 5


async def test_fence_and_rally_types_are_kept_apart() -> None:
    mock = MockAutopilot(0, mission=survey(3), bind_port=free_udp_port(), send_port=free_udp_port())
    async with mock:
        client = _Client(mock)
        await client.start()
        fence = [item(i, 5003, 47.39 + i * 1e-3, 8.54).replace(mission_type=1) for i in range(4)]
        await client.upload(fence, mission_type=1)
        assert len(mock.stores[1]) == 4 and len(mock.mission) == 3
        client.send(lambda m: m.mission_clear_all_encode(1, 1, 1))
        await asyncio.sleep(0.1)
        assert mock.stores[1] == [] and len(mock.mission) == 3
        client.close()


class _Build(Protocol):
    """Makes one message with the client's ``MAVLink``: ``build(mav)``.  (A protocol rather
    than a ``Callable``: mypy cannot infer a lambda with a default argument, such as
    ``lambda m, it=it: ...``, against a ``Callable``.)"""

    def __call__(self, mav: mavlink.MAVLink, /) -> object: ...


class _Client(asyncio.DatagramProtocol):
    """A bare pymavlink ground station, for what MAVSDK's mission_raw does not drive."""

    def __init__(self, mock: MockAutopilot) -> None:
        self.mock = mock
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.inbox: asyncio.Queue[object] = asyncio.Queue()
        self.transport: asyncio.DatagramTransport | None = None

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(
            lambda: self, local_addr=("127.0.0.1", self.mock.send_port)
        )

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        for message in self.mav.parse_buffer(data) or []:
            self.inbox.put_nowait(message)

    def send(self, build: _Build) -> None:
        message = build(self.mav)
        assert self.transport is not None
        self.transport.sendto(message.pack(self.mav), ("127.0.0.1", self.mock.bind_port))  # type: ignore[attr-defined]

    async def expect(self, name: str, timeout: float = 3.0) -> object:
        async with asyncio.timeout(timeout):
            while True:
                message = await self.inbox.get()
                if message.get_type() == name:  # type: ignore[attr-defined]
                    return message

    async def upload(self, items: list[MissionItem], mission_type: int = 0) -> None:
        self.send(lambda m: m.mission_count_encode(1, 1, len(items), mission_type))
        for _ in items:
            request = await self.expect("MISSION_REQUEST_INT")
            it = items[request.seq].replace(mission_type=mission_type)  # type: ignore[attr-defined]
            self.send(lambda m, it=it: item_message(m, 1, 1, it))
        ack = await self.expect("MISSION_ACK")
        assert ack.type == mavlink.MAV_MISSION_ACCEPTED  # type: ignore[attr-defined]

    def command(self, command: int, p1: float = 0, p7: float = 0) -> None:
        self.send(lambda m: m.command_long_encode(1, 1, command, 0, p1, 0, 0, 0, 0, 0, p7))

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


FAST = FlightModel(
    time_scale=20.0,
    rate_hz=20.0,
    craft=Kinematics(cruise_m_s=10.0, climb_m_s=5.0, takeoff_delay_s=0.0),
)


async def _flying(mock: MockAutopilot) -> _Client:
    client = _Client(mock)
    await client.start()
    client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    await client.expect("COMMAND_ACK")
    client.command(mavlink.MAV_CMD_MISSION_START)
    await client.expect("COMMAND_ACK")
    return client


@pytest.mark.slow
async def test_simulated_flight_and_an_upload_in_flight() -> None:
    """Arm, start the mission, fly; an upload mid-flight continues at the current item."""
    legs = [item(i, 16, HOME[0] + 0.0005 * i, HOME[1], 20.0) for i in range(4)]
    mock = MockAutopilot(
        0, mission=legs, flight=FAST, bind_port=free_udp_port(), send_port=free_udp_port()
    )
    async with mock:
        client = await _flying(mock)
        async with asyncio.timeout(10):
            while mock.current < 2:
                await asyncio.sleep(0.05)
        raised = [it.replace(z=it.z + 10.0) if it.seq >= 2 else it for it in legs]
        await client.upload(raised)
        assert mock.current == 2  # continues at the current item, now higher
        async with asyncio.timeout(10):
            while mock.mission_running:
                await asyncio.sleep(0.05)
        client.close()
    top = max(alt for _, _, _, alt in mock.trajectory)
    assert top == pytest.approx(HOME[2] + 30.0, abs=0.6)
    final = mock.trajectory[-1]
    assert final[1] == pytest.approx(legs[-1].x / 1e7, abs=2e-5)


async def test_standalone_mock_autopilot_process(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``python -m companion mock-autopilot`` as a separate process, read by MAVSDK."""
    import sys

    from companion.mission.files import format_wpl
    from protocol.tools.cli import write_atomic

    path = tmp_path / "mission.txt"
    write_atomic(path, format_wpl(survey(6), HOME))
    instance = 37  # binds 14617, sends to 14577
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "companion",
        "mock-autopilot",
        "--mission",
        str(path),
        "--instance",
        str(instance),
        "--trajectory",
        str(tmp_path / "track.csv"),
        stdout=asyncio.subprocess.PIPE,
    )
    try:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), 20)).decode()
        assert "system 38" in line and "14617" in line
        ap = await Autopilot.connect(f"udpin://127.0.0.1:{14540 + instance}")
        try:
            assert _means(False, survey(6), await ap.download())
        finally:
            await ap.close()
    finally:
        proc.terminate()
        await asyncio.wait_for(proc.wait(), 20)
    assert proc.returncode == 0
    assert (tmp_path / "track.csv").read_text().startswith("t_s,lat_deg,lon_deg,alt_m_amsl\n")


@pytest.mark.slow
async def test_takeoff_rtl_and_land_items_are_flown() -> None:
    legs = [
        item(0, 22, HOME[0], HOME[1], 15.0),  # take-off here (PX4 needs the position)
        item(1, 16, HOME[0] + 0.0005, HOME[1], 15.0),
        item(2, 178, frame=2, param1=5.0),  # speed change: skipped in flight
        item(3, 20, frame=2),  # RTL: back over home and land
    ]
    mock = MockAutopilot(
        0, mission=legs, flight=FAST, bind_port=free_udp_port(), send_port=free_udp_port()
    )
    async with mock:
        client = await _flying(mock)
        async with asyncio.timeout(10):
            while len(mock.trajectory) < 20 or mock.armed or mock.alt > 0.05:
                await asyncio.sleep(0.05)
        client.close()
    top = max(alt for _, _, _, alt in mock.trajectory)
    assert top == pytest.approx(HOME[2] + 15.0, abs=0.6)
    north = max(lat for _, lat, _, _ in mock.trajectory)
    assert north == pytest.approx(HOME[0] + 0.0005, abs=3e-5)
    _, lat, lon, _ = mock.trajectory[-1]
    assert (lat, lon) == pytest.approx(HOME[:2], abs=3e-5)


async def test_position_telemetry_reaches_mavsdk() -> None:
    async with vehicle(survey(3)) as (_, ap):
        lat, lon, alt = await ap.position()
    assert (lat, lon) == pytest.approx(HOME[:2], abs=1e-6)
    assert alt == pytest.approx(HOME[2], abs=0.01)
