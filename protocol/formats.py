"""Reading paths from files: the paper's text format and QGroundControl ``.plan`` missions.

* Paper format: one polyline per line, ``(x,y)(x,y)...`` with integer coordinates; several
  lines are several separate test cases.
* QGroundControl plan (JSON, ``fileType: Plan``): the planned home position followed by every
  mission item that carries a position (waypoint, loiter, land, takeoff, spline waypoint), as
  WGS84 degE7; :class:`~protocol.grid.GridSpec` projects them onto the grid.

Malformed input raises :class:`InputFormatError` naming the file and line.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

from .errors import LocalProtocolError
from .geometry import Point

_POINT = re.compile(r"\(\s*(-?\d+)\s*,\s*(-?\d+)\s*\)")
_LINE = re.compile(r"^(\s*\(\s*-?\d+\s*,\s*-?\d+\s*\)\s*)+$")
MAX_COORDINATE_DIGITS = 10
# MAV_CMD values whose params 5/6 are a position on the flight path.
POSITION_COMMANDS = frozenset({16, 17, 18, 19, 21, 22, 82, 84, 85})


class InputFormatError(LocalProtocolError):
    """A path file could not be read."""


def parse_paper_text(text: str, source: str = "<text>") -> list[tuple[Point, ...]]:
    """Every non-empty line as a polyline of at least two points."""
    cases: list[tuple[Point, ...]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if not _LINE.match(line):
            raise InputFormatError(f"{source}:{number}: expected (x,y)(x,y)..., got {line!r}")
        points: list[Point] = []
        for x, y in _POINT.findall(line):
            if max(len(x.lstrip("-")), len(y.lstrip("-"))) > MAX_COORDINATE_DIGITS:
                raise InputFormatError(f"{source}:{number}: coordinate too large")
            points.append((int(x), int(y)))
        if len(points) < 2:
            raise InputFormatError(f"{source}:{number}: a path needs at least two points")
        cases.append(tuple(points))
    if not cases:
        raise InputFormatError(f"{source}: no paths")
    return cases


def _degE7(value: object, what: str, source: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputFormatError(f"{source}: {what} is not a number")
    return round(value * 1e7)


def parse_plan(text: str, source: str = "<plan>") -> tuple[tuple[int, int], ...]:
    """Positions (lat, lon in degE7) of a QGroundControl plan, home first."""
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise InputFormatError(f"{source}: not JSON: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("fileType") != "Plan":
        raise InputFormatError(f"{source}: not a QGroundControl plan (fileType != Plan)")
    mission = doc.get("mission")
    if not isinstance(mission, dict) or not isinstance(mission.get("items"), list):
        raise InputFormatError(f"{source}: plan has no mission items")
    points: list[tuple[int, int]] = []
    home = mission.get("plannedHomePosition")
    if isinstance(home, list) and len(home) >= 2:
        points.append(
            (_degE7(home[0], "home latitude", source), _degE7(home[1], "home longitude", source))
        )
    for index, item in enumerate(mission["items"]):
        if not isinstance(item, dict) or item.get("type") != "SimpleItem":
            raise InputFormatError(f"{source}: mission item {index} is not a SimpleItem")
        params = item.get("params")
        if item.get("command") not in POSITION_COMMANDS:
            continue
        if not isinstance(params, list) or len(params) != 7:
            raise InputFormatError(f"{source}: mission item {index} needs 7 params")
        lat = _degE7(params[4], f"item {index} latitude", source)
        lon = _degE7(params[5], f"item {index} longitude", source)
        if lat == 0 and lon == 0:
            continue  # takeoff/land "here"
        if not points or points[-1] != (lat, lon):
            points.append((lat, lon))
    if len(points) < 2:
        raise InputFormatError(f"{source}: a path needs at least two positions")
    return tuple(points)


def read_text(path: str | Path) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFormatError(f"{path}: {exc}") from exc
