"""Reading paths from files in the paper's text format: one polyline per line,
``(x,y)(x,y)...`` with integer coordinates; several lines are several separate test cases.
A line may give every vertex an altitude, ``(x,y,z)``, or an altitude and a time,
``(x,y,z,t)`` (grid units and seconds: the path as flown, :func:`route_of`).

Mission files (QGroundControl ``.plan``, ``QGC WPL``) are not read here: the ground path a
mission flies (launch leg, loiter circles, DO_JUMP loops, RTL) is the companion's one model,
``companion.mission.flightpath``; ``python -m companion compare`` reads them with it.

Malformed input raises :class:`InputFormatError` naming the file and line.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Sequence
from pathlib import Path

from protocol.errors import LocalProtocolError
from protocol.geo.volumes import Route

_POINT = re.compile(r"\(\s*(-?\d+(?:\s*,\s*-?\d+){1,3})\s*\)")
_LINE = re.compile(r"^(\s*\(\s*-?\d+(?:\s*,\s*-?\d+){1,3}\s*\)\s*)+$")
MAX_COORDINATE_DIGITS = 10
Vertex = tuple[int, ...]  # (x, y), (x, y, z) or (x, y, z, t)


class InputFormatError(LocalProtocolError):
    """A path file could not be read."""


def parse_paper_text(text: str, source: str = "<text>") -> list[tuple[Vertex, ...]]:
    """Every non-empty line as a polyline of at least two vertices, all of one kind."""
    cases: list[tuple[Vertex, ...]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if not _LINE.match(line):
            raise InputFormatError(
                f"{source}:{number}: expected (x,y)(x,y)... (or (x,y,z), (x,y,z,t)), got {line!r}"
            )
        vertices: list[Vertex] = []
        for group in _POINT.findall(line):
            fields = [f.strip() for f in group.split(",")]
            if max(len(f.lstrip("-")) for f in fields) > MAX_COORDINATE_DIGITS:
                raise InputFormatError(f"{source}:{number}: coordinate too large")
            vertices.append(tuple(int(f) for f in fields))
        if len({len(v) for v in vertices}) != 1:
            raise InputFormatError(f"{source}:{number}: every vertex needs the same fields")
        if len(vertices) < 2:
            raise InputFormatError(f"{source}:{number}: a path needs at least two points")
        if len(vertices[0]) == 4 and any(a[3] > b[3] for a, b in itertools.pairwise(vertices)):
            raise InputFormatError(f"{source}:{number}: times must not decrease along a path")
        cases.append(tuple(vertices))
    if not cases:
        raise InputFormatError(f"{source}: no paths")
    return cases


def read_text(path: str | Path) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFormatError(f"{path}: {exc}") from exc


def route_of(vertices: Sequence[Vertex], time_tolerance: int = 0) -> Route:
    """The path as flown: each segment's band spans its two altitudes (a ramp), its window
    its two times widened by ``time_tolerance`` seconds on either side."""
    points = tuple((v[0], v[1]) for v in vertices)
    pairs = list(itertools.pairwise(vertices))
    bands = (
        tuple((min(a[2], b[2]), max(a[2], b[2])) for a, b in pairs)
        if len(vertices[0]) >= 3
        else None
    )
    windows = (
        tuple((a[3] - time_tolerance, b[3] + time_tolerance) for a, b in pairs)
        if len(vertices[0]) == 4
        else None
    )
    return Route(points, bands, windows)
