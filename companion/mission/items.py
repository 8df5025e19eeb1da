"""Mission items as the autopilot holds them (MAVLink MISSION_ITEM_INT), pure: the item,
its strict checks and normalisation.  Which ground path the items fly is
:mod:`companion.mission.flightpath`; what each autopilot does with them is
:mod:`companion.mission.personalities`.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

from companion.errors import CompanionError

# MAV_CMD values of NAV items that carry a position
NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME = 16, 17, 18, 19
NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF, NAV_LOITER_TO_ALT = 20, 21, 22, 31
NAV_SPLINE_WAYPOINT, NAV_VTOL_TAKEOFF, NAV_VTOL_LAND = 82, 84, 85
POSITIONAL_NAV = frozenset(
    {
        NAV_WAYPOINT,
        NAV_LOITER_UNLIM,
        NAV_LOITER_TURNS,
        NAV_LOITER_TIME,
        NAV_LAND,
        NAV_TAKEOFF,
        NAV_LOITER_TO_ALT,
        NAV_SPLINE_WAYPOINT,
        NAV_VTOL_TAKEOFF,
        NAV_VTOL_LAND,
    }
)
# MAV_FRAME: altitude reference of global frames
FRAMES_AMSL = frozenset({0, 5})  # GLOBAL, GLOBAL_INT
FRAMES_RELATIVE = frozenset({3, 6})  # GLOBAL_RELATIVE_ALT(_INT)
FRAMES_TERRAIN = frozenset({10, 11})  # GLOBAL_TERRAIN_ALT(_INT)
FRAMES_GLOBAL = FRAMES_AMSL | FRAMES_RELATIVE | FRAMES_TERRAIN
# No drone flies 20 km above or below its home or sea level: a larger altitude is a typo.
MAX_ALTITUDE_M = 20_000.0
KNOWN_FRAMES = FRAMES_GLOBAL | {1, 2, 4, 7, 8, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21}
MISSION_TYPES = {0: "mission", 1: "fence", 2: "rally"}


class MissionError(CompanionError):
    """A mission (from a file or from the autopilot) is invalid; says which item and why."""


@dataclass(frozen=True, slots=True)
class MissionItem:
    """One MISSION_ITEM_INT: x/y are degE7 in global frames, z metres in the item's frame."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = 0

    @property
    def has_position(self) -> bool:
        return (
            self.command in POSITIONAL_NAV
            and self.frame in FRAMES_GLOBAL
            and not (self.x == 0 and self.y == 0)
        )

    def check(self, where: str | None = None) -> None:
        """Bounds and sizes of every field (items arrive from files and from the vehicle);
        errors start with ``where`` (default: the item's number)."""
        where = where or f"item {self.seq}"
        if not 0 <= self.seq <= 0xFFFF or not 0 <= self.command <= 0xFFFF:
            raise MissionError(f"{where}: seq/command out of range")
        if self.frame not in KNOWN_FRAMES:
            raise MissionError(f"{where}: unknown frame {self.frame}")
        if self.current not in (0, 1) or self.autocontinue not in (0, 1):
            raise MissionError(f"{where}: current/autocontinue must be 0 or 1")
        if self.mission_type not in MISSION_TYPES:
            raise MissionError(f"{where}: unknown mission type {self.mission_type}")
        if not -(2**31) <= self.x < 2**31 or not -(2**31) <= self.y < 2**31:
            raise MissionError(f"{where}: x/y outside int32")
        if self.frame in FRAMES_GLOBAL and (
            abs(self.x) > 900_000_000 or abs(self.y) > 1_800_000_000
        ):
            raise MissionError(f"{where}: latitude/longitude out of range")
        if not math.isfinite(self.z):
            raise MissionError(f"{where}: altitude is not a number")
        if self.frame in FRAMES_GLOBAL and abs(self.z) > MAX_ALTITUDE_M:
            raise MissionError(
                f"{where}: altitude {self.z:g} m is out of range (at most {MAX_ALTITUDE_M:g} m "
                "from home or sea level)"
            )
        for name in ("param1", "param2", "param3"):
            if math.isinf(getattr(self, name)):
                raise MissionError(f"{where}: {name} is infinite")

    def replace(self, **changes: Any) -> MissionItem:
        return replace(self, **changes)

    def same_as(self, other: MissionItem) -> bool:
        """Equal as the vehicle stores them (float32 params, NaN equal to NaN)."""

        def f32(v: float) -> float:
            return float(struct.unpack("<f", struct.pack("<f", v))[0])

        def eq(a: float, b: float) -> bool:
            return (math.isnan(a) and math.isnan(b)) or f32(a) == f32(b)

        return (
            self.seq,
            self.frame,
            self.command,
            self.current,
            self.autocontinue,
            self.x,
            self.y,
            self.mission_type,
        ) == (
            other.seq,
            other.frame,
            other.command,
            other.current,
            other.autocontinue,
            other.x,
            other.y,
            other.mission_type,
        ) and all(
            eq(getattr(self, n), getattr(other, n))
            for n in ("param1", "param2", "param3", "param4", "z")
        )


P = TypeVar("P")


def point_as_segment(path: Sequence[P]) -> list[P]:
    """A path of one vertex (a drone holding position) as one zero-length segment."""
    return list(path) * 2 if len(path) == 1 else list(path)


def normalise(items: Sequence[MissionItem]) -> list[MissionItem]:
    """Sequence numbers 0..n-1 and exactly one current item (the first marked, else 0)."""
    marked = [i for i, item in enumerate(items) if item.current]
    current = marked[0] if marked else 0
    out = [item.replace(seq=i, current=int(i == current)) for i, item in enumerate(items)]
    for item in out:
        item.check()
    return out
