"""The mock autopilot's flight: the stored mission flown by the product's flight model.

In simulated seconds of its clock, the vehicle flies as
:class:`companion.mission.flight_model.Flight` says PX4 does (take-off climb, 3-D legs with
altitude ramps, speeding up and slowing down, corners, loiter times, DO_JUMP loops as the firmware
counts them, landing at LAND and at the end of RTL, a hover at the end of the mission) -- the same
model the companion predicts its
windows and bands from.  A new mission leaves the current item where the firmware would (PX4:
at the item the upload marks current, in flight too; ArduPilot: where it was, item 1 on the
ground).  What the vehicle reports goes out through its MAVLink endpoint
(:class:`~companion.sim.mock_autopilot.MockAutopilot`), which this class leaves to hooks.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from companion.mission.flight_model import Flight, Kinematics
from companion.mission.items import MissionItem
from companion.mission.personalities import personality
from companion.radio.clock import Clock
from companion.sim.mock_links import Faults
from companion.sim.mock_missions import MissionServer


@dataclass(frozen=True)
class FlightModel:
    """The simulated multicopter -- PX4's kinematics (:class:`Kinematics`) at this cruise
    speed (MPC_XY_CRUISE: DO_CHANGE_SPEED items override it), or ``craft`` whole -- and how
    fast simulated time runs."""

    cruise_m_s: float = 10.0
    time_scale: float = 1.0  # simulated seconds per real second
    rate_hz: float = 10.0
    craft: Kinematics | None = None

    @property
    def kinematics(self) -> Kinematics:
        return self.craft or Kinematics(cruise_m_s=self.cruise_m_s)


class MockFlight(MissionServer):
    """The stored mission (:class:`MissionServer`) flown by the flight model."""

    def __init__(
        self,
        *,
        mission: list[MissionItem] | None,
        home: tuple[float, float, float],
        ardupilot: bool,
        faults: Faults | None,
        flight: FlightModel | None,
        clock: Clock | None,
    ) -> None:
        super().__init__(personality(ardupilot), home, faults or Faults(), mission)
        self.ardupilot = ardupilot
        self._model = flight or FlightModel()
        # Simulated seconds: a replay's clock, shared by its vehicles and radio, or else the
        # monotonic clock at the flight model's time scale (0: time stands still).
        scale = self._model.time_scale
        self.now: Callable[[], float] = (
            clock.now if clock is not None else lambda: time.monotonic() * scale
        )
        self.craft = Flight(
            self._model.kinematics, home, self.mission, self.personality.home_is_item0
        )
        self.craft.current = 1 if ardupilot and len(self.mission) > 1 else 0
        self.craft.on_reached = self._reached_item
        self.craft.on_current = self._report_current
        self.trajectory: list[tuple[float, float, float, float]] = []
        self.reached: list[int] = []  # items reached in flight, in order (MISSION_ITEM_REACHED)
        self.origin = 0.0

    @property
    def flight(self) -> FlightModel:
        return self._model

    @flight.setter
    def flight(self, model: FlightModel) -> None:
        """Another vehicle from now on (tests step a stopped mock by hand, faster)."""
        self._model = model
        self.craft.kinematics = model.kinematics
        self.craft.cruise = model.kinematics.cruise_m_s

    # The vehicle's state is the flight model's.
    @property
    def current(self) -> int:
        return self.craft.current

    @current.setter
    def current(self, value: int) -> None:
        self.craft.current = value

    @property
    def lat(self) -> float:
        return self.craft.lat

    @property
    def lon(self) -> float:
        return self.craft.lon

    @property
    def alt(self) -> float:
        """Metres above home."""
        return self.craft.alt

    @property
    def armed(self) -> bool:
        return self.craft.armed

    @armed.setter
    def armed(self, value: bool) -> None:
        self.craft.armed = value

    @property
    def flying(self) -> bool:
        return self.craft.flying

    @property
    def mission_running(self) -> bool:
        return self.craft.mission_running

    @property
    def holding(self) -> bool:
        return self.craft.holding

    @property
    def _sim_time(self) -> float:
        return self.craft.t

    def _reached_item(self, seq: int) -> None:
        self.reached.append(seq)
        self._item_reached(seq)

    def _item_reached(self, seq: int) -> None:
        """Hook: the vehicle reached item ``seq`` (the endpoint sends MISSION_ITEM_REACHED)."""
        raise NotImplementedError

    def _mission_replaced(self, marked: int | None) -> None:
        """PX4 restarts at the item marked current (in flight too), else keeps its index;
        ArduPilot ignores the mark: keeps its index in flight, item 1 on the ground."""
        craft = self.craft
        craft.items = self.mission
        last = max(len(self.mission) - 1, 0)
        before = craft.current
        if self.personality.home_is_item0:
            craft.current = min(craft.current, last) if craft.flying else min(1, last)
        elif marked is not None:
            craft.current = min(marked, last)
            craft.restart()  # the item starts again
        else:
            craft.current = min(craft.current, last)
        if craft.current != before:
            craft.restart()
        if len(self.mission) <= int(self.personality.home_is_item0):  # nothing left to fly
            craft.mission_running = False
        craft.clear_jumps()

    def _mission_cleared(self) -> None:
        self.craft.items = self.mission
        self.craft.current = 0
        self.craft.mission_running = False
        self.craft.clear_jumps()

    def _set_current(self, seq: int) -> bool:
        if not 0 <= seq < len(self.mission):
            return False
        if seq != self.craft.current:
            self.craft.restart()
        self.craft.current = seq
        return True

    def _startable(self) -> bool:
        """Would the firmware fly this mission?  (PX4 denies a take-off at 0,0: "first
        waypoint too far from home".)"""
        p = self.personality
        return bool(self.mission) and not (
            p.problems(self.mission) or p.start_problems(self.mission)
        )

    def take_off(self) -> None:
        """Armed, flying the mission from the current item (what arm + MISSION_START do)."""
        self._start_mission()

    def pause(self) -> None:
        """Hold where it is, as the operator's hold switch (AUTO.LOITER) does in flight."""
        if self.flying:
            self._hold()

    def resume(self) -> None:
        """Fly the mission on from the current item (AUTO.MISSION again)."""
        if self.armed and self.mission and self._startable():
            self._start_mission()

    def _start_mission(self) -> None:
        self.craft.items = self.mission
        self.craft.start()

    def _guided_takeoff(self, alt: float) -> None:
        """MAV_CMD_NAV_TAKEOFF outside a mission: climb to ``alt`` above home and hover."""
        self.craft.takeoff_alt = alt
        self.craft.flying = True

    def _hold(self) -> None:
        self.craft.hold()

    def restart_clock(self, origin: float) -> None:
        """Make ``origin`` (a time of :attr:`now`) simulated time zero; forget the track."""
        self.origin, self.craft.t = origin, 0.0
        self.trajectory.clear()

    def advance(self, dt: float) -> None:
        """One step of the flight model, recorded in the trajectory."""
        self.craft.step(dt)
        craft = self.craft
        self.trajectory.append((craft.t, craft.lat, craft.lon, self.home[2] + craft.alt))

    def sim_time(self) -> float:
        """Simulated seconds since ``origin`` (shared by the vehicles of a replay)."""
        return self.now() - self.origin
