"""The ground path a mission flies, as the autopilot flies it (pure): one model for the CLI,
the companion, the replays and the mock autopilot.

What the comparison must see is every leg the vehicle flies, not only the legs between
waypoints (``docs/autopilot.md``):

* the **launch leg** from home to the first position (a TAKEOFF without a position is at home);
* **DO_JUMP** loops: the items between the target and the jump flown again, and the leg back
  to the target (:func:`flight_order`; the path takes each jump once -- another pass flies the
  same ground track --, the flight model of the mock takes every repetition);
* **RETURN_TO_LAUNCH**: the leg home;
* **loiter circles**: a loiter with a radius is the polygon circumscribing its circle, entered
  and left through its centre (conservative: anything that crosses the circle crosses the
  polygon); a loiter without a radius (multicopters hover) is its point.

Each vertex names the item it belongs to and whether an altitude edit may move it: waypoints
and loiters may; home, take-off, landing and RTL never move.  Segment k joins vertex k and
k + 1 -- of this list, so the protocol's segment k and the planner's segment k agree.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

from companion.mission.items import (
    NAV_LOITER_TIME,
    NAV_LOITER_TO_ALT,
    NAV_LOITER_TURNS,
    NAV_LOITER_UNLIM,
    NAV_RETURN_TO_LAUNCH,
    NAV_SPLINE_WAYPOINT,
    NAV_WAYPOINT,
    MissionError,
    MissionItem,
)
from protocol.geo.geodesy import ground_offset, moved

DO_JUMP = 177
JUMP_TAG, DO_JUMP_TAG = 600, 601  # ArduPilot: a jump to the JUMP_TAG item with tag param1
MAX_ORDER = 4096  # items in one flown order (bounds loops of loops)
LOITER_SIDES = 8
# Points this close are one place: PX4's HOME_POSITION is a few cm off the home it was given
# (3 cm measured on SITL), and a take-off "here" must not add a leg of that length.
SAME_PLACE_M = 1.0
MOVABLE = frozenset(
    {
        NAV_WAYPOINT,
        NAV_SPLINE_WAYPOINT,
        NAV_LOITER_UNLIM,
        NAV_LOITER_TURNS,
        NAV_LOITER_TIME,
        NAV_LOITER_TO_ALT,
    }
)
LOITERS = frozenset({NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME, NAV_LOITER_TO_ALT})


class VertexKind(enum.Enum):
    HOME = "home"  # where the vehicle starts (launch leg) or returns to (RTL)
    POSITION = "position"  # a NAV item's position
    LOITER = "loiter"  # a corner of a loiter's polygon


@dataclass(frozen=True, slots=True)
class Vertex:
    lat: int  # degE7
    lon: int
    items: tuple[int, ...]  # the mission items flown here (none: home before the first item)
    kind: VertexKind
    moves: tuple[int, ...]  # those of them an altitude edit may move

    @property
    def point(self) -> tuple[int, int]:
        return self.lat, self.lon


@dataclass(frozen=True)
class FlightPath:
    """The flown ground path: vertices in flight order."""

    vertices: tuple[Vertex, ...]

    @property
    def points(self) -> list[tuple[int, int]]:
        return [v.point for v in self.vertices]

    @property
    def segments(self) -> int:
        return max(len(self.vertices) - 1, 0)

    def items_of(self, segment: int) -> list[int]:
        """The movable items at the two ends of ``segment`` (empty: altitude edits cannot
        change this leg, e.g. the launch leg to a take-off point)."""
        if not 0 <= segment < self.segments:
            raise MissionError(f"segment {segment} outside 0..{self.segments - 1}")
        ends = (self.vertices[segment], self.vertices[segment + 1])
        return sorted({i for v in ends for i in v.moves})

    def start_at(self, current: int) -> int:
        """Index of the first segment still to fly when item ``current`` is active: the leg
        that ends at the first vertex of that item (or of a later one)."""
        for k, v in enumerate(self.vertices):
            if v.items and max(v.items) >= current:
                return max(k - 1, 0)
        return max(len(self.vertices) - 2, 0)


def jump_target(items: Sequence[MissionItem], jump: MissionItem) -> int:
    """The index a DO_JUMP (param1: the item number) or DO_JUMP_TAG (param1: a JUMP_TAG's
    tag) continues at."""
    target = jump.param1
    if jump.command == DO_JUMP_TAG:
        for k, it in enumerate(items):
            if it.command == JUMP_TAG and it.param1 == target:
                return k
        raise MissionError(f"item {jump.seq}: DO_JUMP_TAG to tag {target}: no JUMP_TAG has it")
    if not math.isfinite(target) or not 0 <= int(target) < len(items):
        raise MissionError(f"item {jump.seq}: DO_JUMP to {target}, outside 0..{len(items) - 1}")
    return int(target)


def flight_order(
    items: Sequence[MissionItem],
    *,
    first: int = 0,
    max_jumps: int | None = 1,
    limit: int = MAX_ORDER,
) -> list[int]:
    """Item indices in the order the autopilot executes them, from ``first``: each DO_JUMP
    taken as often as its repeat count says (param2; -1: for ever), but at most ``max_jumps``
    times when set; the walk ends after RTL or a final LAND, or at ``limit`` items."""
    counts: dict[int, int] = {}
    order: list[int] = []
    i = first
    while 0 <= i < len(items) and len(order) < limit:
        item = items[i]
        if item.command in (DO_JUMP, DO_JUMP_TAG):
            target = jump_target(items, item)
            wanted = int(item.param2) if math.isfinite(item.param2) else 0
            if wanted < 0:
                wanted = max_jumps if max_jumps is not None else limit
            elif max_jumps is not None:
                wanted = min(wanted, max_jumps)
            if counts.get(i, 0) < wanted:
                counts[i] = counts.get(i, 0) + 1
                order.append(i)  # counters live for the whole mission (PX4 and ArduPilot
                i = target  # reset them only when the mission restarts), nested loops too
                continue
        order.append(i)
        if item.command == NAV_RETURN_TO_LAUNCH:
            break
        i += 1
    return order


def _loiter_radius_m(item: MissionItem) -> float:
    """A loiter's circle radius from its own parameter (0: hover over the point)."""
    raw = item.param2 if item.command == NAV_LOITER_TO_ALT else item.param3
    return abs(raw) if math.isfinite(raw) else 0.0


def _circle(lat: int, lon: int, radius_m: float) -> list[tuple[int, int]]:
    """Corners of the regular polygon around the circle (its sides touch the circle)."""
    reach = radius_m / math.cos(math.pi / LOITER_SIDES) + 1.0  # + 1 m for rounding
    lat_deg = lat / 1e7
    out = []
    for k in range(LOITER_SIDES):
        a = 2 * math.pi * k / LOITER_SIDES
        north, east = reach * math.cos(a), reach * math.sin(a)
        to_lat, to_lon = moved(lat_deg, lon / 1e7, north, east)
        out.append((round(to_lat * 1e7), round(to_lon * 1e7)))
    return out


def _same_place(a: tuple[int, int], b: tuple[int, int]) -> bool:
    north, east = ground_offset(a[0] / 1e7, a[1] / 1e7, b[0] / 1e7, b[1] / 1e7)
    return math.hypot(north, east) <= SAME_PLACE_M


def flight_path(
    items: Sequence[MissionItem],
    home: tuple[int, int] | None,
    *,
    ardupilot: bool = False,
) -> FlightPath:
    """The ground path of ``items`` flown from ``home`` (degE7; ArduPilot: item 0 when not
    given; None: unknown, the path starts at the first position)."""
    first = 0
    if ardupilot:
        first = 1
        if home is None and items and items[0].has_position:
            home = (items[0].x, items[0].y)
    out: list[Vertex] = []

    def add(lat: int, lon: int, item: int | None, kind: VertexKind, movable: bool) -> None:
        items: tuple[int, ...] = () if item is None else (item,)
        moves = items if movable else ()
        if out and _same_place(out[-1].point, (lat, lon)):  # nothing flown between them
            last = out[-1]
            items = last.items + tuple(i for i in items if i not in last.items)
            moves = last.moves + tuple(i for i in moves if i not in last.moves)
            kind = VertexKind.HOME if VertexKind.HOME in (kind, last.kind) else last.kind
            out[-1] = Vertex(last.lat, last.lon, items, kind, moves)
            return
        out.append(Vertex(lat, lon, items, kind, moves))

    if home is not None:
        add(home[0], home[1], None, VertexKind.HOME, False)
    for i in flight_order(items, first=first):
        it = items[i]
        if it.command == NAV_RETURN_TO_LAUNCH:
            if home is not None:
                add(home[0], home[1], i, VertexKind.HOME, False)
            continue
        if not it.has_position:
            continue
        movable = it.command in MOVABLE
        add(it.x, it.y, i, VertexKind.POSITION, movable)
        radius = _loiter_radius_m(it) if it.command in LOITERS else 0.0
        if radius >= 1.0:
            corners = _circle(it.x, it.y, radius)
            for lat, lon in [*corners, corners[0]]:
                add(lat, lon, i, VertexKind.LOITER, movable)
            add(it.x, it.y, i, VertexKind.POSITION, movable)
    return FlightPath(tuple(out))
