"""The vehicles a replay flies: the mock autopilot, or PX4 SITL (SIH) from a build.

Both give the replay the same handful of things: a MAVLink URL for the companion's MAVSDK,
take-off, whether the vehicle is still flying its mission, the track flown (simulated
seconds on the replay's clock, lat, lon, alt AMSL) and the mission it holds at the end.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import Protocol

from companion.mission.items import MissionItem
from companion.radio.clock import Clock
from companion.sim.mock_autopilot import Faults, FlightModel, MockAutopilot
from companion.sim.px4 import Px4Build, Px4Error, Px4Vehicle
from companion.sim.px4.link import PX4_AUTO_LOITER, PX4_AUTO_MISSION, PX4_MODE_AUTO
from companion.tasks import spawn

Track = list[tuple[float, float, float, float]]  # (simulated s, lat, lon, alt AMSL)
RESOLVED_TOLERANCE_M = 0.5  # two mocks: a pair is resolved at the offset minus this
SAMPLE_S = 0.05  # real seconds between track samples of a PX4 vehicle
HELD_TRIES = 3  # downloads of the mission a PX4 vehicle holds, before giving up
log = logging.getLogger(__name__)


class ReplayVehicle(Protocol):
    kind: str  # "mock" or "px4-sitl", as the report says
    altitude_accuracy_m: float  # how far its altitude strays from the planned one in flight

    @property
    def api_url(self) -> str: ...

    @property
    def flying(self) -> bool: ...

    @property
    def trajectory(self) -> Track: ...

    async def start(self, origin: float) -> None: ...

    def restart_clock(self, origin: float) -> None: ...

    async def take_off(self) -> None: ...

    async def pause(self) -> None: ...

    async def resume(self) -> None: ...

    async def held_mission(self) -> list[MissionItem]: ...

    async def stop(self) -> None: ...


class MockVehicle:
    """The mock autopilot on loopback UDP ports of its own."""

    kind = "mock"
    altitude_accuracy_m = RESOLVED_TOLERANCE_M / 2  # the kinematic model flies exactly

    def __init__(
        self,
        mission: list[MissionItem],
        home: tuple[float, float, float],
        *,
        ardupilot: bool,
        flight: FlightModel,
        faults: Faults,
        bind_port: int,
        send_port: int,
        clock: Clock,
    ) -> None:
        self.mock = MockAutopilot(
            0,
            mission=mission,
            home=home,
            ardupilot=ardupilot,
            flight=flight,
            faults=faults,
            bind_port=bind_port,
            send_port=send_port,
            clock=clock,
        )

    @property
    def api_url(self) -> str:
        return f"udpin://127.0.0.1:{self.mock.send_port}"

    @property
    def flying(self) -> bool:
        return self.mock.mission_running or self.mock.holding

    @property
    def trajectory(self) -> Track:
        return self.mock.trajectory

    async def start(self, origin: float) -> None:
        await self.mock.start(origin)

    def restart_clock(self, origin: float) -> None:
        self.mock.restart_clock(origin)

    async def take_off(self) -> None:
        self.mock.take_off()

    async def pause(self) -> None:
        self.mock.pause()

    async def resume(self) -> None:
        self.mock.resume()

    async def held_mission(self) -> list[MissionItem]:
        return list(self.mock.mission)

    async def stop(self) -> None:
        await self.mock.stop()


class Px4SitlVehicle:
    """A PX4 SITL (SIH) vehicle started from ``build``: the mission is uploaded over its
    ground-station link before the companion starts, take-off is MISSION_START.  Its track is
    sampled on the replay's clock (two SITL processes keep lock-step time each on its own:
    their clocks drift apart when the machine cannot keep up, the replay's does not)."""

    kind = "px4-sitl"
    # PX4's altitude controller in SIH: up to 0.8 m above a hover's planned altitude and
    # 0.6 m on a raised leg, measured in the crossing replay (docs/companion.md)
    altitude_accuracy_m = 0.75

    def __init__(
        self,
        build: Px4Build,
        mission: list[MissionItem],
        home: tuple[float, float, float],
        *,
        speed_factor: float,
        cruise_m_s: float,
        clock: Clock,
    ) -> None:
        params = {"MPC_XY_CRUISE": cruise_m_s, "MPC_XY_VEL_MAX": max(cruise_m_s, 12.0)}
        self.vehicle = Px4Vehicle(build, home=home, speed_factor=speed_factor, params=params)
        self.mission = mission
        self.speed_factor = speed_factor
        self._track: Track = []
        self.clock = clock  # lock-step SITL keeps real time: the replay's plain scaled clock
        self._origin = 0.0
        self._sampler: asyncio.Task[None] | None = None

    @property
    def api_url(self) -> str:
        return self.vehicle.api_url

    @property
    def flying(self) -> bool:
        return self.vehicle.has_been_armed and not self.vehicle.finished

    @property
    def trajectory(self) -> Track:
        return self._track

    async def start(self, origin: float) -> None:
        self._origin = origin
        await self.vehicle.start()
        await self.vehicle.upload_mission(self.mission)
        self._sampler = spawn(self._sample(), name="px4-track-sampler", log=log)

    def restart_clock(self, origin: float) -> None:
        self._origin = origin
        self._track.clear()

    async def _sample(self) -> None:
        while True:
            position = self.vehicle.position
            if position is not None:
                now = self.clock.now() - self._origin
                self._track.append((now, *position))
            await asyncio.sleep(SAMPLE_S)

    async def take_off(self) -> None:
        await self.vehicle.take_off()

    async def pause(self) -> None:
        """AUTO.LOITER, as MAVSDK's pause_mission and a ground station's hold switch."""
        await self.vehicle.set_mode(PX4_MODE_AUTO, PX4_AUTO_LOITER)

    async def resume(self) -> None:
        await self.vehicle.set_mode(PX4_MODE_AUTO, PX4_AUTO_MISSION)

    async def held_mission(self) -> list[MissionItem]:
        """What PX4 holds, read over the GCS link.  PX4 runs one mission transfer at a time:
        one the companion's MAVSDK left unfinished when it stopped blocks ours until PX4
        times it out, so a silent PX4 is asked again after a pause."""
        for attempt in range(HELD_TRIES):
            try:
                return await self.vehicle.download_mission()
            except Px4Error:
                if attempt == HELD_TRIES - 1:
                    raise
                await asyncio.sleep(1.0)
        raise AssertionError("unreachable")

    async def stop(self) -> None:
        if self._sampler is not None:
            self._sampler.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._sampler
        await self.vehicle.stop()
