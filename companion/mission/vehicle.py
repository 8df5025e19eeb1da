"""What the autopilot's telemetry says of the vehicle: where it is, how it moves, whether it is
armed, holding, on the ground, which item it flies to.

The runtime feeds it (:meth:`Vehicle.moved`, :meth:`Vehicle.arming`, ...) from MAVSDK's
streams; every other part reads it.  Speeds are smoothed over about a second of positions.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from companion.mission.ground import distance_m


@dataclass
class VehicleState:
    position: tuple[int, int, float] = (0, 0, 0.0)  # lat, lon degE7, alt AMSL
    position_at: float = 0.0  # when it came (link seconds): the state a prediction starts at
    relative_alt: float = 0.0
    armed: bool = False
    speed_m_s: float = 0.0
    climb_m_s: float = 0.0  # vertical speed, up
    held: bool = False  # holding in the air (paused, or the mission over): flies on when?
    current_item: int = 0
    has_flown: bool = False  # airborne at least once since the companion started
    heard_at: float = field(default_factory=time.monotonic)  # the last position (real seconds)
    _last: tuple[float, tuple[int, int], float] | None = None  # for speeds: (when, where, alt)

    @property
    def on_ground(self) -> bool:
        """On the ground and not leaving it: an armed vehicle below 1 m is taking off (a
        departure is flight: its runs are in-flight runs)."""
        return self.relative_alt < 1.0 and not self.armed

    def here(self) -> tuple[int, int] | None:
        """Where the drone is, for distances along its path (None on the ground)."""
        return None if self.on_ground or self.position[:2] == (0, 0) else self.position[:2]

    def moved(
        self, lat_deg: float, lon_deg: float, amsl_m: float, relative_m: float, now: float
    ) -> bool:
        """A position from the autopilot at link time ``now``; True when it took off."""
        self.heard_at = time.monotonic()
        self.position = (round(lat_deg * 1e7), round(lon_deg * 1e7), amsl_m)
        self.position_at = now
        was_on_ground = self.on_ground
        self.relative_alt = relative_m
        took_off = was_on_ground and not self.on_ground
        if took_off:
            self.has_flown = True
        last = self._last
        if last is None or now - last[0] >= 1.0:
            if last is not None:
                moved = distance_m(last[1], self.position[:2]) / (now - last[0])
                self.speed_m_s = 0.5 * (self.speed_m_s + moved)
                self.climb_m_s = (self.relative_alt - last[2]) / (now - last[0])
            self._last = (now, self.position[:2], self.relative_alt)
        return took_off

    def arming(self, armed: bool) -> bool:
        """The armed state from the autopilot; True when the vehicle departs (armed low)."""
        departing = armed and not self.armed and self.relative_alt < 1.0
        if departing:
            self.has_flown = True  # departing: its path is flown from here on
        self.armed = armed
        return departing
