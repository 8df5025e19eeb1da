"""The mock autopilot's flight: a kinematic multicopter flying the stored mission.

In simulated seconds of its clock, the vehicle climbs and flies straight at cruise speed to
each positional item, holds over LOITER_TIME items, follows DO_JUMP loops (bounded, as the
firmware counts them), lands at LAND and at the end of RTL, and holds where it is at the end
of the mission.  A new mission leaves the current item where the firmware would (PX4: at the
item the upload marks current, in flight too; ArduPilot: where it was, item 1 on the ground).
What the vehicle reports goes out through its MAVLink endpoint
(:class:`~companion.sim.mock_autopilot.MockAutopilot`), which this class leaves to hooks.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from protocol.geodesy import ground_offset, moved

from ..autopilots import personality
from ..flightpath import DO_JUMP
from ..link.clock import Clock
from ..mission import (
    FRAMES_AMSL,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    MissionItem,
)
from .mock_links import Faults
from .mock_missions import MissionServer


@dataclass(frozen=True)
class FlightModel:
    """Kinematics of the simulated multicopter and how fast simulated time runs."""

    cruise_m_s: float = 10.0
    climb_m_s: float = 3.0
    acceptance_m: float = 2.0
    time_scale: float = 1.0  # simulated seconds per real second
    rate_hz: float = 10.0


class MockFlight(MissionServer):
    """The stored mission (:class:`MissionServer`) flown by the kinematic model."""

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
        self.flight = flight or FlightModel()
        # Simulated seconds: a replay's clock, shared by its vehicles and radio, or else the
        # monotonic clock at the flight model's time scale (0: time stands still).
        scale = self.flight.time_scale
        self.now: Callable[[], float] = (
            clock.now if clock is not None else lambda: time.monotonic() * scale
        )
        self.current = 1 if ardupilot and len(self.mission) > 1 else 0
        self.lat, self.lon, self.alt = home[0], home[1], 0.0  # alt: metres above home
        self.armed = False
        self.flying = False
        self.mission_running = False
        self.holding = False  # paused in flight (hold / loiter mode)
        self.trajectory: list[tuple[float, float, float, float]] = []
        self.reached: list[int] = []  # items reached in flight, in order (MISSION_ITEM_REACHED)
        self.origin = 0.0
        self._sim_time = 0.0
        self._takeoff_alt: float | None = None
        self._rtl_descending = False
        self._hold_until: float | None = None

    def _item_reached(self, seq: int) -> None:
        """Hook: the vehicle reached item ``seq`` (the endpoint sends MISSION_ITEM_REACHED)."""
        raise NotImplementedError

    def _mission_replaced(self, marked: int | None) -> None:
        """PX4 restarts at the item marked current (in flight too), else keeps its index;
        ArduPilot ignores the mark: keeps its index in flight, item 1 on the ground."""
        last = max(len(self.mission) - 1, 0)
        before = self.current
        if self.personality.home_is_item0:
            self.current = min(self.current, last) if self.flying else min(1, last)
        elif marked is not None:
            self.current = min(marked, last)
            self._hold_until, self._rtl_descending = None, False  # the item starts again
        else:
            self.current = min(self.current, last)
        if self.current != before:
            self._hold_until, self._rtl_descending = None, False
        if len(self.mission) <= int(self.personality.home_is_item0):  # nothing left to fly
            self.mission_running = False
        self._jumps.clear()

    def _mission_cleared(self) -> None:
        self.current = 0
        self.mission_running = False
        self._jumps.clear()

    def _set_current(self, seq: int) -> bool:
        if not 0 <= seq < len(self.mission):
            return False
        if seq != self.current:
            self._hold_until, self._rtl_descending = None, False
        self.current = seq
        return True

    def _startable(self) -> bool:
        """Would the firmware fly this mission?  (PX4 denies a take-off at 0,0: "first
        waypoint too far from home".)"""
        p = self.personality
        return bool(self.mission) and not (
            p.problems(self.mission) or p.start_problems(self.mission)
        )

    def _target(self, item: MissionItem) -> tuple[float, float, float] | None:
        """(lat, lon, metres above home) the vehicle flies to for this item, if any."""
        if item.command == NAV_RETURN_TO_LAUNCH:  # home at the current height, then down
            return self.home[0], self.home[1], 0.0 if self._rtl_descending else self.alt
        if item.command == NAV_TAKEOFF and not item.has_position:
            return self.lat, self.lon, item.z - (self.home[2] if item.frame in FRAMES_AMSL else 0)
        if not item.has_position:
            return None
        alt = item.z - self.home[2] if item.frame in FRAMES_AMSL else item.z
        if item.command == NAV_LAND:
            alt = 0.0
        return item.x / 1e7, item.y / 1e7, alt

    def _go_to(self, index: int | None) -> None:
        if index is None:
            self.mission_running = False  # end of the mission: hold position (PX4: loiter)
        else:
            self.current = index
        self._report_current()

    def _step(self, dt: float) -> None:
        f = self.flight
        target = None
        if self.mission_running and self.current < len(self.mission):
            if self.ardupilot and self.current == 0:  # home is not flown to
                self.current = 1
                return
            if self.mission[self.current].command == DO_JUMP:
                self._go_to(self._resolve(self.current))
                return
            target = self._target(self.mission[self.current])
            if target is None:  # an item without a position: done at once
                self._advance()
                return
        elif self._takeoff_alt is not None:
            target = (self.lat, self.lon, self._takeoff_alt)
        if target is None or not self.flying:
            return
        north, east = ground_offset(self.lat, self.lon, target[0], target[1])
        dist = math.hypot(north, east)
        step = min(dist, f.cruise_m_s * dt)
        if dist > 0:
            self.lat, self.lon = moved(self.lat, self.lon, north * step / dist, east * step / dist)
        dz = target[2] - self.alt
        self.alt += max(-f.climb_m_s * dt, min(f.climb_m_s * dt, dz))
        if dist - step <= f.acceptance_m and abs(target[2] - self.alt) <= 0.5:
            if self.mission_running:
                self._advance()
            else:
                self._takeoff_alt = None

    def _advance(self) -> None:
        """The current item is reached (or has no position): report it and go on."""
        item = self.mission[self.current]
        if item.command == NAV_LOITER_TIME and item.has_position:
            if self._hold_until is None:
                self._hold_until = self._sim_time + max(item.param1, 0.0)
            if self._sim_time < self._hold_until:
                return  # holding over the loiter point
            self._hold_until = None
        if item.command == NAV_RETURN_TO_LAUNCH and not self._rtl_descending:
            self._rtl_descending = True  # over home: now land there
            return
        self.reached.append(self.current)
        self._item_reached(self.current)
        if item.command in (NAV_LAND, NAV_RETURN_TO_LAUNCH):
            self.alt, self.armed = 0.0, False
            self.mission_running = self.flying = self._rtl_descending = False
            self._report_current()
        else:
            self._go_to(self._resolve(self.current + 1))

    def take_off(self) -> None:
        """Armed, flying the mission from the current item (what arm + MISSION_START do)."""
        self._start_mission()

    def _start_mission(self) -> None:
        if not self.flying:  # a new flight: the mission starts again, jump counters too
            self._jumps.clear()
        self.armed = self.flying = self.mission_running = True

    def restart_clock(self, origin: float) -> None:
        """Make ``origin`` (a time of :attr:`now`) simulated time zero; forget the track."""
        self.origin, self._sim_time = origin, 0.0
        self.trajectory.clear()

    def advance(self, dt: float) -> None:
        """One step of the flight model, recorded in the trajectory."""
        self._sim_time += dt
        self._step(dt)
        self.trajectory.append((self._sim_time, self.lat, self.lon, self.home[2] + self.alt))

    def sim_time(self) -> float:
        """Simulated seconds since ``origin`` (shared by the vehicles of a replay)."""
        return self.now() - self.origin
