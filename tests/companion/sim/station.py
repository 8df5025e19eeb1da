"""A raw-pymavlink ground station for the mock autopilot's tests, and small mission helpers."""

from __future__ import annotations

import asyncio
import struct
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any, Protocol

from pymavlink.dialects.v20 import common as mavlink

from companion.mission.flight_model import Kinematics
from companion.mission.items import MissionItem
from companion.sim.mock_autopilot import FlightModel, MockAutopilot, item_message
from companion.sim.mock_missions import item_from
from companion.sim.replay import free_udp_port as free_port
from tests.companion.missions import HOME, item

FROZEN = FlightModel(time_scale=0.0)  # simulated time stands still: nothing moves by itself
# a vehicle that gets anywhere at once (tests of the mission protocol, not of the kinematics)
FAST = FlightModel(
    craft=Kinematics(
        cruise_m_s=50.0,
        speed_factor=1.0,
        accel_m_s2=500.0,
        climb_m_s=50.0,
        descend_m_s=50.0,
        vertical_accel_m_s2=500.0,
        takeoff_delay_s=0.0,
    )
)
LAT, LON = HOME[0], HOME[1]


def f32(v: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def legs(n: int, alt: float = 30.0) -> list[MissionItem]:
    """n waypoints 55 m apart, northwards from home."""
    return [item(i, 16, LAT + 0.0005 * (i + 1), LON, alt) for i in range(n)]


def home_item(home: tuple[float, float, float] = HOME) -> MissionItem:
    """ArduPilot's item 0: home, AMSL."""
    return item(0, 16, *home, frame=0).replace(param4=0.0)


class Build(Protocol):
    """Makes one message with the station's ``MAVLink``: ``build(mav)``.  (A protocol rather
    than ``Callable[[Any], Any]``: mypy cannot infer a lambda with a default argument, such as
    ``lambda m, seq=seq: ...``, against a ``Callable``.)"""

    def __call__(self, mav: Any, /) -> Any: ...


class Where(Protocol):
    """Picks the messages :meth:`Station.expect` waits for: ``where(message)``."""

    def __call__(self, message: Any, /) -> bool: ...


class Station(asyncio.DatagramProtocol):
    """A bare pymavlink ground station: sends to one port of the mock, queues what comes."""

    def __init__(self, to_port: int, sysid: int = 255) -> None:
        self.to_port = to_port
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=190)
        self.inbox: asyncio.Queue[Any] = asyncio.Queue()
        self.transport: asyncio.DatagramTransport | None = None
        self.requested: list[int] = []  # the items the mock asked for in the last upload

    @classmethod
    async def open(cls, to_port: int, bind_port: int = 0, sysid: int = 255) -> Station:
        station = cls(to_port, sysid)
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(lambda: station, local_addr=("127.0.0.1", bind_port))
        return station

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        for message in self.mav.parse_buffer(data) or []:
            self.inbox.put_nowait(message)

    def send(self, build: Build) -> None:
        assert self.transport is not None
        self.transport.sendto(build(self.mav).pack(self.mav), ("127.0.0.1", self.to_port))

    def forget(self) -> None:
        while not self.inbox.empty():
            self.inbox.get_nowait()

    async def expect(self, *names: str, timeout: float = 3.0, where: Where | None = None) -> Any:
        """The next message of one of the types ``names`` (and ``where``), others dropped."""
        async with asyncio.timeout(timeout):
            while True:
                m = await self.inbox.get()
                if m.get_type() in names and (where is None or where(m)):
                    return m

    async def silent(self, name: str, seconds: float) -> bool:
        """No ``name`` arrives within ``seconds``."""
        try:
            await self.expect(name, timeout=seconds)
        except TimeoutError:
            return True
        return False

    def command(self, command: int, p1: float = 0, p2: float = 0, p3: float = 0) -> None:
        self.send(lambda m: m.command_long_encode(1, 1, command, 0, p1, p2, p3, 0, 0, 0, 0))

    async def upload(
        self, items: list[MissionItem], mission_type: int = 0, *, legacy: bool = False
    ) -> int:
        """Answer the mock's requests until it acknowledges; the MAV_MISSION_RESULT."""
        self.forget()
        self.requested = []
        self.send(lambda m: m.mission_count_encode(1, 1, len(items), mission_type))
        for _ in range(4 * len(items) + 8):  # a few re-requests at most
            m = await self.expect("MISSION_REQUEST_INT", "MISSION_ACK")
            if m.get_type() == "MISSION_ACK":
                return int(m.type)
            self.requested.append(m.seq)
            it = items[m.seq].replace(seq=m.seq, mission_type=mission_type)
            self.send(lambda mav, it=it: item_message(mav, 1, 1, it, legacy=legacy))  # degrees
        raise AssertionError("the upload never ended")

    async def download(self, mission_type: int = 0) -> list[MissionItem]:
        self.forget()
        self.send(lambda m: m.mission_request_list_encode(1, 1, mission_type))
        count = (await self.expect("MISSION_COUNT")).count
        out = []
        for seq in range(count):
            self.send(lambda m, seq=seq: m.mission_request_int_encode(1, 1, seq, mission_type))
            r = await self.expect("MISSION_ITEM_INT", where=lambda m, seq=seq: m.seq == seq)
            out.append(item_from(r, legacy=False))
        return out

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


@asynccontextmanager
async def mock_and_station(
    mission: list[MissionItem] | None = None, **kwargs: Any
) -> AsyncIterator[tuple[MockAutopilot, Station]]:
    """A started mock on free ports (GCS link off) and a station on its API link."""
    bind, send = free_port(), free_port()
    kwargs.setdefault("flight", FROZEN)
    mock = MockAutopilot(0, mission=mission, bind_port=bind, send_port=send, **kwargs)
    async with mock:
        station = await Station.open(bind, send)
        try:
            yield mock, station
        finally:
            station.close()


# ---------------------------------------------------------------------- personality
