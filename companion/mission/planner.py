"""Altitude-offset planner (pure): fly the flagged segments higher (or lower), the whole of them.

Segment k joins vertices k and k+1 of the flown path (:class:`companion.mission.flightpath.
FlightPath`).  Every *movable* item at either end of a flagged segment (waypoints and
loiters) is moved by the segment's raise (the offset, or more: :mod:`companion.mission.levels`; an
item between two flagged segments takes the larger), in the item's own frame (relative,
AMSL or terrain: a metre is a metre in each).  Landing, RTL and every item without a
position are never moved.  An autopilot flies a leg as a straight 3-D line, so the leg
*before* a flagged run climbs, the flagged run is flown at the raised altitude from end to
end, and the first unflagged leg after it descends (:func:`plan_offsets`).  Where the start
of a flagged segment cannot be raised that way :func:`plan_edit` does what the autopilot
needs for the whole raise over the whole segment: before take-off it raises the take-off
altitude (the launch leg then starts at the raised height); in flight on the flagged leg
itself it inserts a waypoint where the vehicle is, at the raised altitude (it climbs there
at once, then flies level) and marks it current.  A leg whose end cannot move (the last leg
into a landing) is named by :func:`fixed_segments`.  A limit a raise would break is an
error, never a silent clip.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from companion.mission.flightpath import DO_JUMP, FlightPath
from companion.mission.items import (
    FRAMES_AMSL,
    FRAMES_GLOBAL,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    MissionError,
    MissionItem,
)
from protocol.geo.geodesy import ground_offset, moved


class PlannerError(MissionError):
    """The requested edit is impossible within the limits (or names unknown segments)."""


@dataclass(frozen=True, slots=True)
class OffsetSettings:
    offset_m: float = 10.0
    direction: str = "up"  # "up" or "down"
    max_altitude_m: float = 120.0  # relative / terrain frames (height above home or ground)
    min_altitude_m: float = 5.0  # relative / terrain frames, when going down
    max_altitude_amsl_m: float | None = None  # AMSL frames, if the operator sets one
    # Offsets a raise may climb above the plan; a conflict no raise that low clears is
    # resolved by time instead (a hold before it: companion.runs.edits).  None: up to the
    # ceiling (then a hold).  Off by default: docs/companion.md says why.
    max_levels: int | None = None

    def __post_init__(self) -> None:
        if not self.offset_m > 0:
            raise PlannerError("offset must be positive (choose the direction separately)")
        if self.direction not in ("up", "down"):
            raise PlannerError(f"direction must be 'up' or 'down', not {self.direction!r}")
        if self.max_levels is not None and self.max_levels < 1:
            raise PlannerError(f"max_levels must be at least 1, not {self.max_levels}")

    @property
    def max_raise_m(self) -> float:
        """The largest raise before a hold (inf: none)."""
        return math.inf if self.max_levels is None else self.max_levels * self.offset_m

    @property
    def delta(self) -> float:
        return self.offset_m if self.direction == "up" else -self.offset_m


def fixed_segments(path: FlightPath, flagged: Iterable[int]) -> list[int]:
    """The flagged segments an altitude edit cannot change (no movable item at either end)."""
    return sorted(k for k in set(flagged) if not path.items_of(k))


def plan_offsets(
    items: Sequence[MissionItem],
    flagged: Iterable[int] | Mapping[int, float],
    settings: OffsetSettings | None = None,
    *,
    path: FlightPath,
) -> list[MissionItem]:
    """The edited mission: the movable items of every flagged segment of ``path`` (the
    flown path of ``items``) moved by the offset, or by the segment's own raise in metres
    when ``flagged`` maps segments to raises (in the direction's sign)."""
    settings = settings or OffsetSettings()
    raises = (
        {k: float(v) for k, v in flagged.items()}
        if isinstance(flagged, Mapping)
        else dict.fromkeys(flagged, settings.delta)
    )
    segments = sorted(raises)
    if segments and not 0 <= segments[0] <= segments[-1] < path.segments:
        raise PlannerError(f"segments {segments} outside 0..{path.segments - 1}")
    moved: dict[int, float] = {}
    for k, delta in raises.items():
        for index in path.items_of(k):
            if index >= len(items):
                raise PlannerError(f"segment {k}: item {index} is not in the mission")
            moved[index] = max(moved.get(index, 0.0), delta, key=abs)
    out = list(items)
    for index in sorted(moved):
        out[index] = _raised(items[index], moved[index], settings, index)
    return out


def _raised(item: MissionItem, delta: float, settings: OffsetSettings, index: int) -> MissionItem:
    """The item ``delta`` metres higher, within the limits."""
    z = item.z + delta
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
    return item.replace(z=z)


@dataclass(frozen=True)
class Vehicle:
    """Where the vehicle is for an edit: ``segment`` it flies in flight (None: on the
    ground), its position (degE7) and altitude above home and AMSL; ``lead_per_m``: metres
    flown while climbing one metre at its speed and climb rate (an inserted waypoint goes
    that far ahead for the climb it needs, so the vehicle climbs on without stopping)."""

    segment: int | None
    lat: int
    lon: int
    relative_m: float
    amsl_m: float
    lead_per_m: float = 0.0


@dataclass(frozen=True)
class Edit:
    """A mission to upload: ``items``, and per item the original item it is (an inserted
    waypoint: the one it precedes); ``inserted``: the inserted waypoint's index, if any."""

    items: list[MissionItem]
    origin: tuple[int, ...]
    inserted: int | None = None

    def index_of(self, original: int) -> int:
        """Where original item ``original`` is in this edit."""
        for i, o in enumerate(self.origin):
            if o == original and i != self.inserted:
                return i
        return len(self.items) - 1


def plan_edit(
    items: Sequence[MissionItem],
    raises: Mapping[int, float],
    settings: OffsetSettings,
    *,
    path: FlightPath,
    vehicle: Vehicle,
) -> Edit:
    """The edit that flies every raised segment at its raise from end to end (module
    docstring): :func:`plan_offsets`, then the take-off raised before take-off, or a
    waypoint inserted where the vehicle is when it flies a raised segment already."""
    out = plan_offsets(items, raises, settings, path=path)
    origin = tuple(range(len(out)))
    if vehicle.segment is None:  # on the ground: the launch leg starts at the take-off height
        _raise_takeoff(items, out, raises, settings, path)
        return Edit(out, origin)
    k = vehicle.segment
    if k not in raises:
        return Edit(out, origin)
    ahead = [i for i in path.vertices[min(k + 1, len(path.vertices) - 1)].items if i < len(out)]
    if not ahead:
        return Edit(out, origin)
    before = min(ahead)
    target = items[before]
    frame = target.frame if target.frame in FRAMES_GLOBAL else 3
    here = vehicle.amsl_m if frame in FRAMES_AMSL else vehicle.relative_m
    raised = out[before].z if before in path.items_of(k) else target.z + raises[k]
    if abs(here - raised) <= 1.0 or (raises[k] > 0) != (raised > here):
        return Edit(out, origin)  # at (or past) the raised altitude already
    waypoint = _climb_waypoint(vehicle, target, frame, here, raised)
    waypoint = _raised(waypoint, raised - here, settings, before)
    edited = _inserted(out, waypoint, before)
    return Edit(edited, (*origin[:before], before, *origin[before:]), before)


def _raise_takeoff(
    items: Sequence[MissionItem],
    out: list[MissionItem],
    raises: Mapping[int, float],
    settings: OffsetSettings,
    path: FlightPath,
) -> None:
    """Raise in ``out`` every take-off at the start of a raised segment by that segment's
    raise, where that lifts it more than :func:`plan_offsets` did."""
    for k, delta in raises.items():
        for index in path.vertices[k].items:
            if items[index].command == NAV_TAKEOFF and index < len(out):
                lifted = _raised(items[index], delta, settings, index)
                if abs(lifted.z - items[index].z) > abs(out[index].z - items[index].z):
                    out[index] = lifted


def _climb_waypoint(
    vehicle: Vehicle, target: MissionItem, frame: int, here: float, raised: float
) -> MissionItem:
    """A waypoint at the vehicle's altitude ``here`` (in ``frame``), toward ``target`` by the
    lead the climb to ``raised`` needs (not within 10 m of ``target``)."""
    north, east = ground_offset(
        vehicle.lat / 1e7, vehicle.lon / 1e7, target.x / 1e7, target.y / 1e7
    )
    left = math.hypot(north, east)
    lead = min(vehicle.lead_per_m * abs(raised - here), max(left - 10.0, 0.0))
    lat, lon = moved(
        vehicle.lat / 1e7, vehicle.lon / 1e7, *(c * lead / max(left, 1e-9) for c in (north, east))
    )
    return MissionItem(
        0,
        frame,
        NAV_WAYPOINT,
        0,
        1,
        0.0,
        0.0,
        0.0,
        float("nan"),
        round(lat * 1e7),
        round(lon * 1e7),
        here,
    )


def _inserted(out: Sequence[MissionItem], waypoint: MissionItem, before: int) -> list[MissionItem]:
    """``out`` with ``waypoint`` inserted at index ``before``, renumbered; jumps to the items
    that moved on by one follow them."""
    edited = [*out[:before], waypoint, *out[before:]]
    return [
        it.replace(seq=i, param1=it.param1 + 1)
        if it.command == DO_JUMP and math.isfinite(it.param1) and it.param1 >= before
        else it.replace(seq=i)
        for i, it in enumerate(edited)
    ]
