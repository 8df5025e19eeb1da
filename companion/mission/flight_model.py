"""How a multicopter flies its mission, as PX4 v1.16 does where separation depends on it (pure).

One model for the mock autopilot, which flies it (:mod:`companion.sim.mock_flight`), and for
the companion, which predicts from it when its drone will be where and at what altitude (the
time windows and altitude bands of its protected volumes, :mod:`companion.mission.schedule`).  The
figures are fitted to flights measured on PX4 v1.16 SITL (``../shared/px4-traces``; the
fit and its residuals: docs/autopilot.md):

* **take-off**: about 5.5 s from arming to lift-off, then a vertical climb, speeding up at
  0.4 m/s^2 to 3 m/s and slowing down before the altitude (30 m in 17 s, 20 m in 15 s);
* **a leg is the straight 3-D line** from where it starts to its waypoint: the altitude ramps
  with the distance flown (35.1 m in the middle of a leg from 30 m to 40 m), at most 3 m/s up
  and 1.5 m/s down (the leg is flown slower where a ramp needs it);
* **speed**: the cruise speed (MPC_XY_CRUISE, or a DO_CHANGE_SPEED item) flown at 0.945 of
  it (7.55 m/s at 8), reached and left at 0.73 m/s^2 (PX4's jerk-limited profile: a stop and
  a start cost about 10 s against flying through);
* **corners** at PX4's corner speed sqrt(a r tan(alpha / 2)) with a = 1.5 m/s^2 (MPC_XY_TRAJ_P x
  MPC_ACC_HOR), r = 2 m (NAV_ACC_RAD) and alpha the angle at the waypoint (straight on: no
  slowing; a right angle: 1.7 m/s); the vehicle stops at a loiter, a waypoint with a hold
  time, a landing and the end of the mission;
* **holds** (a paused mission): the vehicle brakes to a hover where it is.

ArduPilot Copter flies waypoint legs as straight 3-D lines too (its documentation); the same
model stands for it.  Everything is in simulated seconds; nothing here reads a clock.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from companion.mission.flightpath import DO_JUMP, jump_target
from companion.mission.items import (
    FRAMES_AMSL,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_LOITER_UNLIM,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    MissionError,
    MissionItem,
)
from protocol.geo.geodesy import ground_offset, moved

DO_CHANGE_SPEED = 178
MAX_PREDICTION_S = 4 * 3600.0  # a prediction stops here (a loiter without end, a jump loop)


@dataclass(frozen=True)
class Kinematics:
    """The vehicle's kinematics (defaults: PX4 v1.16 SITL quadrotor, measured)."""

    cruise_m_s: float = 10.0  # MPC_XY_CRUISE: until a DO_CHANGE_SPEED item says otherwise
    speed_factor: float = 0.945  # the share of the commanded speed flown
    accel_m_s2: float = 0.73  # horizontal speeding up and slowing down
    corner_accel_m_s2: float = 1.5  # MPC_XY_TRAJ_P x MPC_ACC_HOR: the corner speed's limit
    acceptance_m: float = 2.0  # NAV_ACC_RAD: a waypoint is reached this close
    climb_m_s: float = 3.0  # MPC_Z_V_AUTO_UP
    descend_m_s: float = 1.5  # MPC_Z_V_AUTO_DN
    vertical_accel_m_s2: float = 0.4
    takeoff_delay_s: float = 5.5  # arming to lift-off

    def flown(self, commanded: float) -> float:
        return max(commanded * self.speed_factor, 0.1)


@dataclass(frozen=True, slots=True)
class Reached:
    """An item reached: when (simulated seconds), where (altitude above home) and when the
    vehicle left it (after a loiter's time; ``None`` while it holds there)."""

    item: int
    t: float
    alt: float
    left: float | None = None


@dataclass
class Flight:
    """The vehicle flying ``items`` from ``home`` (lat, lon in degrees, altitude AMSL):
    where it is, how fast, which item it flies to, stepped by :meth:`step`.  The mock
    autopilot drives one (uploads, commands, modes); :meth:`predict` flies a copy to the end.
    ``home_is_item0``: ArduPilot's item 0 is home, never flown to."""

    kinematics: Kinematics
    home: tuple[float, float, float]
    items: list[MissionItem] = field(default_factory=list)
    home_is_item0: bool = False
    current: int = 0
    lat: float = math.nan
    lon: float = math.nan
    alt: float = 0.0  # metres above home
    speed: float = 0.0  # horizontal, along the leg
    vz: float = 0.0
    armed: bool = False
    flying: bool = False
    mission_running: bool = False
    holding: bool = False
    t: float = 0.0
    reached: list[Reached] = field(default_factory=list)
    on_reached: Callable[[int], None] | None = None
    on_current: Callable[[], None] | None = None
    cruise: float = math.nan  # commanded, m/s
    takeoff_alt: float | None = None  # a guided take-off (MAV_CMD_NAV_TAKEOFF), no mission
    _jumps: dict[int, int] = field(default_factory=dict)
    # the leg under way: (item, its target), where it started (lat, lon, alt) and its length
    _leg: tuple[int, tuple[float, float, float], float, float, float, float] | None = None
    _hold_until: float | None = None
    _rtl_down: bool = False
    _lift_at: float | None = None  # a take-off from the ground waits until then

    def __post_init__(self) -> None:
        if math.isnan(self.lat):
            self.lat, self.lon = self.home[0], self.home[1]
        if math.isnan(self.cruise):
            self.cruise = self.kinematics.cruise_m_s

    # ------------------------------------------------------------------ what to fly

    def _rel(self, item: MissionItem) -> float:
        """The item's altitude above home (terrain frames taken as above home)."""
        return item.z - self.home[2] if item.frame in FRAMES_AMSL else item.z

    def target(self, index: int) -> tuple[float, float, float] | None:
        """(lat, lon, metres above home) the vehicle flies to for item ``index``, if any."""
        item = self.items[index]
        if item.command == NAV_RETURN_TO_LAUNCH:  # home at the current height, then down
            return self.home[0], self.home[1], 0.0 if self._rtl_down else self.alt
        if item.command == NAV_TAKEOFF:
            if self.alt < self._rel(item) - 0.5 or not item.has_position:
                return self.lat, self.lon, self._rel(item)  # straight up first
            return item.x / 1e7, item.y / 1e7, self._rel(item)
        if not item.has_position:
            return None
        if item.command == NAV_LAND:  # over the point at the current height, then down
            north, east = ground_offset(self.lat, self.lon, item.x / 1e7, item.y / 1e7)
            down = math.hypot(north, east) <= self.kinematics.acceptance_m
            return item.x / 1e7, item.y / 1e7, 0.0 if down else self.alt
        return item.x / 1e7, item.y / 1e7, self._rel(item)

    def _stops_at(self, index: int) -> bool:
        item = self.items[index]
        if item.command == NAV_WAYPOINT:
            return item.param1 > 0 or self._next_position(index) is None
        return item.command != NAV_TAKEOFF or self._next_position(index) is None

    def _next_position(self, index: int) -> tuple[float, float] | None:
        """Where the leg after item ``index`` goes (jumps not followed: a jump's turn is
        flown as a stop), if it is a plain continuation."""
        for item in self.items[index + 1 :]:
            if item.command in (DO_JUMP, NAV_RETURN_TO_LAUNCH, NAV_LAND):
                return None
            if item.has_position:
                return item.x / 1e7, item.y / 1e7
        return None

    def _exit_speed(self, index: int, target: tuple[float, float, float]) -> float:
        """The speed the leg to item ``index`` ends at: 0 for a stop, PX4's corner speed for
        a turn (alpha: the angle at the waypoint between the way in and the way out)."""
        if self._stops_at(index) or self._leg is None:
            return 0.0
        after = self._next_position(index)
        if after is None:
            return 0.0
        _, _, lat0, lon0, _, _ = self._leg
        n_in, e_in = ground_offset(target[0], target[1], lat0, lon0)
        n_out, e_out = ground_offset(target[0], target[1], after[0], after[1])
        norm = math.hypot(n_in, e_in) * math.hypot(n_out, e_out)
        if norm == 0:
            return 0.0
        alpha = math.acos(max(-1.0, min(1.0, (n_in * n_out + e_in * e_out) / norm)))
        k = self.kinematics
        if alpha >= math.pi - 1e-6:
            return k.flown(self.cruise)
        corner = math.sqrt(k.corner_accel_m_s2 * k.acceptance_m * math.tan(alpha / 2))
        return min(corner, k.flown(self.cruise))

    # ------------------------------------------------------------------ items in order

    def jump(self, index: int) -> int | None:
        """Take the DO_JUMP at ``index`` if its repeat count (param2; -1: for ever) allows: its
        target, else None.  As :func:`~companion.mission.flightpath.flight_order`: the counters live
        until the mission restarts (new mission, clear, a new take-off), nested loops too."""
        item = self.items[index]
        try:
            target = jump_target(self.items, item)
        except MissionError:
            return None  # a jump to nowhere: skipped
        wanted = int(item.param2) if math.isfinite(item.param2) else 0
        taken = self._jumps.get(index, 0)
        if 0 <= wanted <= taken:
            return None
        self._jumps[index] = taken + 1
        return target

    def resolve(self, index: int) -> int | None:
        """The item flown from ``index`` on, jumps followed (None: the mission is over)."""
        for _ in range(2 * len(self.items) + 2):  # a loop of jumps only: give up
            if not 0 <= index < len(self.items):
                return None
            if self.items[index].command != DO_JUMP:
                return index
            target = self.jump(index)
            index = index + 1 if target is None else target
        return None

    def restart(self) -> None:
        """The item under way starts again (a new mission, a new current item)."""
        self._hold_until, self._rtl_down, self._leg = None, False, None

    def clear_jumps(self) -> None:
        self._jumps.clear()

    def go_to(self, index: int | None) -> None:
        if index is None:
            self.mission_running = False  # end of the mission: hold position (PX4: loiter)
        else:
            self.current = index
        self.restart()
        if self.on_current is not None:
            self.on_current()

    def start(self) -> None:
        """Armed and flying the mission from the current item (arm + MISSION_START); from
        the ground after the spool-up of a take-off."""
        if not self.flying:  # a new flight: the mission starts again, jump counters too
            self._jumps.clear()
            self._lift_at = self.t + self.kinematics.takeoff_delay_s
        self.armed = self.flying = self.mission_running = True
        self.holding = False

    def loitering(self, for_s: float) -> None:
        """The vehicle has been over its current item's point for ``for_s`` seconds (a
        loiter's or a waypoint's hold time under way): it leaves when that time is up."""
        if not 0 <= self.current < len(self.items) or for_s <= 0:
            return
        item = self.items[self.current]
        if item.command not in (NAV_LOITER_TIME, NAV_WAYPOINT) or not item.has_position:
            return
        wait = item.param1 if math.isfinite(item.param1) else 0.0
        self.reached.append(Reached(self.current, self.t - for_s, self.alt))
        self._hold_until = self.t - for_s + max(wait, 0.0)

    def hold(self) -> None:
        """Pause where the vehicle is (it brakes to a hover)."""
        self.mission_running, self.holding = False, True

    # ------------------------------------------------------------------ kinematics

    def step(self, dt: float) -> None:
        """``dt`` simulated seconds of flight."""
        self.t += dt
        if not self.flying:
            return
        if self._lift_at is not None:
            if self.t < self._lift_at:
                return
            self._lift_at = None
        target = None
        index = self.current
        if self.mission_running and self.current < len(self.items):
            if self.home_is_item0 and self.current == 0:  # home is not flown to
                self.current = 1
                return
            if self.items[self.current].command == DO_CHANGE_SPEED:
                speed = self.items[self.current].param2
                if math.isfinite(speed) and speed > 0:
                    self.cruise = speed
                self._advance()
                return
            if self.items[self.current].command == DO_JUMP:
                self.go_to(self.resolve(self.current))
                return
            target = self.target(self.current)
            if target is None:  # an item without a position: done at once
                self._advance()
                return
        elif self.takeoff_alt is not None:
            target, index = (self.lat, self.lon, self.takeoff_alt), -1
        if target is None:
            self._brake(dt)
            self.vz = 0.0
            return
        if self._fly(index, target, dt):
            if not self.mission_running:
                self.takeoff_alt = None
            elif target != self.target(self.current):
                return  # the next phase of the item (up, then over; over, then down)
            else:
                self._advance()

    def _brake(self, dt: float) -> None:
        self.speed = max(self.speed - self.kinematics.accel_m_s2 * dt, 0.0)

    def _fly(self, index: int, target: tuple[float, float, float], dt: float) -> bool:
        """One step toward ``target``; True once it is reached."""
        k = self.kinematics
        north, east = ground_offset(self.lat, self.lon, target[0], target[1])
        dist = math.hypot(north, east)
        if self._leg is None or self._leg[:2] != (index, target):
            self._leg = (index, target, self.lat, self.lon, self.alt, dist)
        *_, alt0, length = self._leg
        dz = target[2] - self.alt
        if length <= k.acceptance_m:  # straight up or down
            self._brake(dt)
            limit = k.climb_m_s if dz > 0 else k.descend_m_s
            wanted = math.copysign(min(limit, math.sqrt(2 * k.vertical_accel_m_s2 * abs(dz))), dz)
            change = k.vertical_accel_m_s2 * dt
            self.vz += max(-change, min(change, wanted - self.vz))
            climb = self.vz * dt
            if abs(climb) >= abs(dz) or abs(dz) <= 0.05:
                self.alt, self.vz = target[2], 0.0
            else:
                self.alt += climb
            if dist > 0:
                step = min(dist, k.flown(self.cruise) * dt)
                self.lat, self.lon = moved(
                    self.lat, self.lon, north * step / dist, east * step / dist
                )
            return abs(target[2] - self.alt) <= 0.1
        exit_speed = self._exit_speed(index, target) if index >= 0 else 0.0
        wanted = min(
            self._steady_m_s(target, alt0, length),
            math.sqrt(exit_speed**2 + 2 * k.accel_m_s2 * dist),
        )
        wanted = max(wanted, 0.3)  # never stall short of the point
        change = k.accel_m_s2 * dt
        self.speed += max(-change, min(change, wanted - self.speed))
        left = self._along(north, east, dist, min(dist, self.speed * dt), target, alt0, length)
        if left <= k.acceptance_m:
            if exit_speed == 0.0:
                self.speed = min(self.speed, 0.5)
            return True
        return False

    def _steady_m_s(self, target: tuple[float, float, float], alt0: float, length: float) -> float:
        """The speed a leg from ``alt0`` to ``target`` (``length`` long) is flown at between
        speeding up and slowing down: the cruise speed, slower where the straight 3-D line
        would climb or descend faster than allowed."""
        k = self.kinematics
        steady = k.flown(self.cruise)
        ramp = abs(target[2] - alt0)
        if ramp > 0:
            limit = k.climb_m_s if target[2] > alt0 else k.descend_m_s
            steady = min(steady, limit * length / ramp)
        return steady

    def _along(
        self,
        north: float,
        east: float,
        dist: float,
        step: float,
        target: tuple[float, float, float],
        alt0: float,
        length: float,
    ) -> float:
        """``step`` metres toward ``target`` (``dist`` away, at (north, east)) on the leg from
        ``alt0`` (``length`` long), at the leg's altitude there; the distance left."""
        self._move(north, east, dist, step)
        left = max(dist - step, 0.0)
        self.alt = target[2] + (alt0 - target[2]) * (left / length)
        self.vz = 0.0
        return left

    def _move(self, north: float, east: float, dist: float, step: float) -> None:
        """``step`` metres along (north, east), which is ``dist`` long."""
        if dist > 0:
            self.lat, self.lon = moved(self.lat, self.lon, north * step / dist, east * step / dist)

    def _advance(self) -> None:
        """The current item is reached (or has no position): record it and go on."""
        item = self.items[self.current]
        if item.command in (NAV_LOITER_TIME, NAV_WAYPOINT) and item.has_position:
            wait = item.param1 if item.command == NAV_LOITER_TIME else max(item.param1, 0.0)
            if self._hold_until is None:
                self._hold_until = self.t + max(wait if math.isfinite(wait) else 0.0, 0.0)
                self.reached.append(Reached(self.current, self.t, self.alt))
            if self.t < self._hold_until:
                self.speed = 0.0
                return  # holding over the point
            self._left()
        elif item.command == NAV_LOITER_UNLIM and item.has_position:
            if not self.reached or self.reached[-1].item != self.current:
                self.reached.append(Reached(self.current, self.t, self.alt))
            self.speed = 0.0
            return  # for ever
        elif item.command == NAV_RETURN_TO_LAUNCH and not self._rtl_down:
            self._rtl_down = True  # over home: now land there
            return
        elif item.command == NAV_LAND and self.alt > 0.1:
            return  # still descending
        else:
            self.reached.append(Reached(self.current, self.t, self.alt, self.t))
        if self.on_reached is not None:
            self.on_reached(self.current)
        if item.command in (NAV_LAND, NAV_RETURN_TO_LAUNCH):
            self.alt, self.armed, self.speed = 0.0, False, 0.0
            self.mission_running = self.flying = self._rtl_down = False
            if self.on_current is not None:
                self.on_current()
        else:
            self.go_to(self.resolve(self.current + 1))

    def _left(self) -> None:
        last = self.reached[-1]
        self.reached[-1] = Reached(last.item, last.t, last.alt, self.t)

    def _cruise(self, dt: float, most: int) -> bool:
        """Up to ``most`` steps of ``dt`` at once where they are all alike -- a waypoint leg
        flown at its steady speed (no speeding up, not yet slowing down for the waypoint, the
        ramp linear in the distance): what :meth:`step` would fly, in one move.  A
        prediction spends nearly all its steps there (False: nothing skipped)."""
        k, leg = self.kinematics, self._leg
        if leg is None or self._lift_at is not None or not self.mission_running or most < 2:
            return False
        index, target, _, _, alt0, length = leg
        if index != self.current or self.current >= len(self.items):
            return False
        item = self.items[self.current]
        if item.command != NAV_WAYPOINT or not item.has_position or length <= k.acceptance_m:
            return False
        if (self.home_is_item0 and self.current == 0) or target != self.target(self.current):
            return False
        north, east = ground_offset(self.lat, self.lon, target[0], target[1])
        dist = math.hypot(north, east)
        steady = self._steady_m_s(target, alt0, length)
        if abs(self.speed - steady) > 1e-9 or steady < 0.3:
            return False
        exit_speed = self._exit_speed(index, target)
        slowing = (steady**2 - exit_speed**2) / (2 * k.accel_m_s2)  # where the speed limit bites
        each = steady * dt
        # every skipped step starts where its distance still allows the steady speed, and
        # ends beyond the waypoint's acceptance radius (with a step to spare)
        steps = min(most, int((dist - max(slowing, k.acceptance_m + each)) / each))
        if steps < 2:
            return False
        self.t += steps * dt
        self._along(north, east, dist, steps * each, target, alt0, length)
        return True

    # ------------------------------------------------------------------ prediction

    def predict(self, dt: float = 0.5, limit_s: float = MAX_PREDICTION_S) -> list[Reached]:
        """The items still to be reached, flown to the end of the mission on a copy (times
        in this flight's seconds; a loiter without end closes the prediction)."""
        future = copy.copy(self)
        holding = self._hold_until is not None and self.reached and self.reached[-1].left is None
        future.reached = [self.reached[-1]] if holding else []  # a hold time under way
        future._jumps = dict(self._jumps)
        future.on_reached = future.on_current = None
        if not future.flying:
            future.start()
        end = self.t + limit_s
        while future.flying and future.mission_running and future.t < end:
            if not future._cruise(dt, int((end - future.t) / dt)):
                future.step(dt)
            if (
                future.reached
                and future.reached[-1].left is None
                and future.items[future.reached[-1].item].command == NAV_LOITER_UNLIM
            ):
                break
        return future.reached


def fly(
    items: Sequence[MissionItem],
    home: tuple[float, float, float],
    kinematics: Kinematics | None = None,
    *,
    home_is_item0: bool = False,
    dt: float = 0.25,
    limit_s: float = MAX_PREDICTION_S,
) -> tuple[list[tuple[float, float, float, float]], list[Reached]]:
    """The whole flight of ``items`` from the ground at home: the track (t, lat, lon,
    altitude AMSL every ``dt``) and the items reached.  For tests and calibration."""
    flight = Flight(kinematics or Kinematics(), home, list(items), home_is_item0)
    flight.current = 1 if home_is_item0 and len(items) > 1 else 0
    flight.start()
    track = [(0.0, flight.lat, flight.lon, home[2] + flight.alt)]
    while flight.flying and flight.t < limit_s:
        flight.step(dt)
        track.append((flight.t, flight.lat, flight.lon, home[2] + flight.alt))
        if not flight.mission_running:
            break
    return track, flight.reached
