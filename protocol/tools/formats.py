"""Reading paths from files in the paper's text format: one polyline per line,
``(x,y)(x,y)...`` with integer coordinates; several lines are several separate test cases.

Mission files (QGroundControl ``.plan``, ``QGC WPL``) are not read here: the ground path a
mission flies (launch leg, loiter circles, DO_JUMP loops, RTL) is the companion's one model,
``companion.flightpath``; ``python -m companion compare`` reads them with it.

Malformed input raises :class:`InputFormatError` naming the file and line.
"""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import LocalProtocolError
from ..geometry import Point

_POINT = re.compile(r"\(\s*(-?\d+)\s*,\s*(-?\d+)\s*\)")
_LINE = re.compile(r"^(\s*\(\s*-?\d+\s*,\s*-?\d+\s*\)\s*)+$")
MAX_COORDINATE_DIGITS = 10


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


def read_text(path: str | Path) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFormatError(f"{path}: {exc}") from exc
