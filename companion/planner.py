"""Altitude-offset planner (pure): fly the flagged segments higher (or lower), nothing else.

Segment k joins vertices k and k+1 of the flown path (:class:`companion.flightpath.
FlightPath`).  Every *movable* item at either end of a flagged segment (waypoints and
loiters) is moved by the offset times the segment's *level* (1 unless several drones share
the airspace, see :mod:`companion.levels`; an item between two flagged segments takes the
higher level), in the item's own frame (relative, AMSL or terrain: a metre is a metre in
each).  Home, take-off, landing, RTL and every item without a position are never moved; the
item count and the ground track stay exactly as they were.  So the leg before a flagged run
climbs, the flagged run is flown at the offset altitude, and the first unflagged leg after it
descends back to the planned altitude.  A leg with no movable end (the launch leg to a
take-off point, the last leg into a landing) cannot be raised: :func:`fixed_segments` names
them.  A limit the offset would break is an error, never a silent clip.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from .flightpath import FlightPath
from .mission import FRAMES_AMSL, MissionError, MissionItem


class PlannerError(MissionError):
    """The requested edit is impossible within the limits (or names unknown segments)."""


@dataclass(frozen=True, slots=True)
class OffsetSettings:
    offset_m: float = 10.0
    direction: str = "up"  # "up" or "down"
    max_altitude_m: float = 120.0  # relative / terrain frames (height above home or ground)
    min_altitude_m: float = 5.0  # relative / terrain frames, when going down
    max_altitude_amsl_m: float | None = None  # AMSL frames, if the operator sets one

    def __post_init__(self) -> None:
        if not self.offset_m > 0:
            raise PlannerError("offset must be positive (choose the direction separately)")
        if self.direction not in ("up", "down"):
            raise PlannerError(f"direction must be 'up' or 'down', not {self.direction!r}")

    @property
    def delta(self) -> float:
        return self.offset_m if self.direction == "up" else -self.offset_m


def fixed_segments(path: FlightPath, flagged: Iterable[int]) -> list[int]:
    """The flagged segments an altitude edit cannot change (no movable item at either end)."""
    return sorted(k for k in set(flagged) if not path.items_of(k))


def plan_offsets(
    items: Sequence[MissionItem],
    flagged: Iterable[int] | Mapping[int, int],
    settings: OffsetSettings | None = None,
    *,
    path: FlightPath,
) -> list[MissionItem]:
    """The edited mission: the movable items of every flagged segment of ``path`` (the
    flown path of ``items``) moved by the offset (times the segment's level when
    ``flagged`` maps segments to levels)."""
    settings = settings or OffsetSettings()
    levels = dict(flagged) if isinstance(flagged, Mapping) else dict.fromkeys(flagged, 1)
    segments = sorted(levels)
    if segments and not 0 <= segments[0] <= segments[-1] < path.segments:
        raise PlannerError(f"segments {segments} outside 0..{path.segments - 1}")
    if any(level < 1 for level in levels.values()):
        raise PlannerError("levels start at 1")
    moved: dict[int, int] = {}
    for k, level in levels.items():
        for index in path.items_of(k):
            if index >= len(items):
                raise PlannerError(f"segment {k}: item {index} is not in the mission")
            moved[index] = max(moved.get(index, 0), level)
    out = list(items)
    for index in sorted(moved):
        item = items[index]
        z = item.z + settings.delta * moved[index]
        if item.frame in FRAMES_AMSL:
            limit = settings.max_altitude_amsl_m
            if limit is not None and z > limit:
                raise PlannerError(f"item {index}: {z:.1f} m AMSL above the limit {limit} m")
        elif z > settings.max_altitude_m:
            raise PlannerError(
                f"item {index}: {z:.1f} m above the maximum altitude {settings.max_altitude_m} m"
            )
        elif z < settings.min_altitude_m:
            raise PlannerError(
                f"item {index}: {z:.1f} m below the minimum altitude {settings.min_altitude_m} m"
            )
        out[index] = item.replace(z=z)
    return out
