"""A mock vehicle in the companion's own process: replays in virtual time.

:class:`InProcessVehicle` is the mock autopilot (:class:`~companion.sim.mock_autopilot.
MockAutopilot`: the same mission store, the firmware's personality, the same flight model)
with no MAVLink link; :class:`InProcessAutopilot` is what the companion asks of it
(:class:`~companion.mission.autopilot.AutopilotBase`) answered by reading and calling that mock
directly instead of through MAVSDK.  Everything then runs in one event loop -- vehicles,
companions, the simulated radio -- so a replay can run on a virtual clock
(:class:`~companion.radio.clock.VirtualTimeLoop`): minutes of flight in seconds, the same on a
busy machine as on an idle one, and many drones at once.  What it leaves out is MAVLink and
MAVSDK themselves (transfers, their latency and their faults): the replays over MAVSDK
(:mod:`companion.sim.replay` without ``virtual``) keep those.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Sequence
from typing import TypeVar

from companion.mission.autopilot import AutopilotBase, AutopilotError, Position, Timeouts
from companion.mission.items import MissionError, MissionItem, normalise
from companion.radio.clock import Clock
from companion.sim.mock_autopilot import FlightModel, MockAutopilot
from companion.sim.vehicles import MockVehicle

ON_CHANGE_S = 0.5  # link seconds between looks at a state reported on change (armed, ...)
PARKED_S = 1.0  # ... and between positions and looks while the vehicle is parked (disarmed)
T = TypeVar("T")


class InProcessAutopilot(AutopilotBase):
    """The companion's view of ``mock``, a vehicle in this process, on ``clock``."""

    def __init__(self, mock: MockAutopilot, clock: Clock) -> None:
        # transfers are instant here: a read-back settles after the shortest of waits
        super().__init__(Timeouts(settle_s=0.05), mock.personality)
        self.mock = mock
        self.clock = clock

    async def download(self) -> list[MissionItem]:
        items = self.mock.held()
        try:
            return normalise(items) if items else []
        except MissionError as exc:  # (the store holds what the personality keeps)
            raise AutopilotError(f"the vehicle holds an invalid mission: {exc}") from exc

    async def _upload(self, items: Sequence[MissionItem]) -> None:
        self.mock.store(0, list(items))

    async def clear(self) -> None:
        self.mock.clear([0])

    async def home(self, timeout_s: float = 5.0) -> tuple[int, int, float] | None:
        lat, lon, alt = self.mock.home
        return round(lat * 1e7), round(lon * 1e7), alt

    async def pause(self) -> None:
        self.mock.pause()

    async def resume(self) -> None:
        self.mock.resume()

    async def positions(self, rate_hz: float) -> AsyncIterator[Position]:
        """At ``rate_hz``; a vehicle parked on the ground (disarmed) once a second."""
        mock = self.mock
        while True:
            yield Position(mock.lat, mock.lon, mock.home[2] + mock.alt, mock.alt)
            await self.clock.sleep(max(1.0 / rate_hz, PARKED_S) if self._parked else 1.0 / rate_hz)

    @property
    def _parked(self) -> bool:
        return not (self.mock.armed or self.mock.flying)

    async def _on_change(self, state: Callable[[], T]) -> AsyncIterator[T]:
        last: object = object()
        while True:
            now = state()
            if now != last:
                last = now
                yield now
            await self.clock.sleep(PARKED_S if self._parked else ON_CHANGE_S)

    def armed_states(self) -> AsyncIterator[bool]:
        return self._on_change(lambda: self.mock.armed)

    def holding_states(self) -> AsyncIterator[bool]:
        """As the mock's heartbeat says (PX4 AUTO.LOITER): flying, not in the mission."""
        return self._on_change(lambda: self.mock.flying and not self.mock.mission_running)

    def progress(self) -> AsyncIterator[tuple[int, int]]:
        return self._on_change(lambda: (self.mock.current, len(self.mock.mission)))


class InProcessVehicle(MockVehicle):
    """A replay vehicle (:class:`~companion.sim.vehicles.ReplayVehicle`) in this process:
    the mock autopilot flying on the replay's clock, without MAVLink (the MAVLink mock's
    vehicle otherwise)."""

    kind = "in-process"

    def __init__(  # (no ports, no MAVLink faults: nothing goes over a link)
        self,
        mission: list[MissionItem],
        home: tuple[float, float, float],
        *,
        ardupilot: bool,
        flight: FlightModel,
        clock: Clock,
    ) -> None:
        self.mock = MockAutopilot(
            0, mission=mission, home=home, ardupilot=ardupilot, flight=flight, clock=clock
        )
        self.autopilot = InProcessAutopilot(self.mock, clock)

    @property
    def api_url(self) -> str:
        return "in-process"

    async def start(self, origin: float) -> None:
        await self.mock.start(origin, links=False)
