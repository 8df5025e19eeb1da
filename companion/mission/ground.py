"""Distances and cuts along ground paths (degE7 points on the local tangent plane,
:func:`protocol.geo.geodesy.ground_offset`, WGS84): how far apart two points are, how far a
point is from a segment, and which part of a path lies within a distance ahead."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

from protocol.geo.geodesy import ground_offset, moved
from protocol.run import DEFAULT_LIMITS

COVER_ALL = 8  # a near answer's cover counts eighths of the horizon asked: 8 is all of it


def distance_m(a: tuple[int, int], b: tuple[int, int]) -> float:
    """Ground distance between two degE7 points."""
    return math.hypot(*ground_offset(a[0] / 1e7, a[1] / 1e7, b[0] / 1e7, b[1] / 1e7))


def _foot(
    p: tuple[int, int], a: tuple[int, int], b: tuple[int, int]
) -> tuple[float, float, float, float, float]:
    """On the tangent plane at p (metres east, north): a's offset from p, the step from a to
    b, and where along it (0..1) p's foot on segment ab lies."""
    ay, ax = ground_offset(p[0] / 1e7, p[1] / 1e7, a[0] / 1e7, a[1] / 1e7)
    by, bx = ground_offset(p[0] / 1e7, p[1] / 1e7, b[0] / 1e7, b[1] / 1e7)
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else max(0.0, min(1.0, -(ax * dx + ay * dy) / length2))
    return ax, ay, dx, dy, t


def segment_distance_m(p: tuple[int, int], a: tuple[int, int], b: tuple[int, int]) -> float:
    """Ground distance from point p to segment ab (degE7), on the tangent plane at p."""
    ax, ay, dx, dy, t = _foot(p, a, b)
    return math.hypot(ax + t * dx, ay + t * dy)


def cut_behind(
    path: Sequence[tuple[int, int]], position: tuple[int, int], back_m: float
) -> list[tuple[int, int]]:
    """``path`` with its first segment starting ``back_m`` behind ``position``'s foot on it
    (never before its first vertex): what lies further behind is flown.  The drone flies
    the first segment; off it (a climb at its start, a turn) the foot is where it is bound
    to rejoin it."""
    if len(path) < 2:
        return list(path)
    a = path[0]
    _, _, dx, dy, t = _foot(position, a, path[1])
    length = math.hypot(dx, dy)
    t = t - back_m / length if length > 0 else 0.0
    if t <= 0:
        return list(path)
    cut = moved(a[0] / 1e7, a[1] / 1e7, t * dy, t * dx)
    return [(round(cut[0] * 1e7), round(cut[1] * 1e7)), *path[1:]]


def along_segment(a: tuple[int, int], b: tuple[int, int], share: float) -> tuple[int, int]:
    """The point ``share`` of the way from a to b (degE7), on the tangent plane at a (as
    :func:`cut_behind` cuts: on any other tangent plane nearby within a millimetre of the
    straight line, where a point halfway in latitude and longitude is half a metre off a
    5 km leg)."""
    if share <= 0.0:
        return a
    if share >= 1.0:
        return b
    north, east = ground_offset(a[0] / 1e7, a[1] / 1e7, b[0] / 1e7, b[1] / 1e7)
    lat, lon = moved(a[0] / 1e7, a[1] / 1e7, share * north, share * east)
    return round(lat * 1e7), round(lon * 1e7)


def along_m(path: Sequence[tuple[int, int]], position: tuple[int, int] | None = None) -> float:
    """How far it is along ``path`` to its end, from ``position`` (the drone, somewhere on
    the first segment) when given, else from the first vertex."""
    return sum(
        distance_m(position if position is not None and k == 0 else a, b)
        for k, (a, b) in enumerate(itertools.pairwise(path))
    )


def cut_at(
    path: Sequence[tuple[int, int]],
    horizon_m: float,
    position: tuple[int, int] | None = None,
) -> list[tuple[int, int]]:
    """The path up to the first vertex at least ``horizon_m`` ahead (whole segments, so
    nothing is rounded); all of it for a horizon of 0.  Distances count from ``position``
    (the drone, somewhere on the first segment) when given, else from the first vertex."""
    if horizon_m <= 0 or len(path) < 2:
        return list(path)
    out = [path[0]]
    for k, (a, b) in enumerate(itertools.pairwise(path)):
        out.append(b)
        horizon_m -= distance_m(position if position is not None and k == 0 else a, b)
        if horizon_m <= 0:
            break
    return out


def near_cut(
    path: Sequence[tuple[int, int]],
    horizon_m: float,
    position: tuple[int, int] | None = None,
    *,
    least: int = 2,
) -> list[tuple[int, int]]:
    """What a near run compares: :func:`cut_at`, at least ``least`` segments, and then as
    many more as the padding makes free (runs are padded to a power of two, so 3 segments
    cost what 4 do).  A near run that takes them may leave no full run to do, which under a
    duty cycle is the difference between a result and a precaution."""
    if horizon_m <= 0 or len(path) < 2:
        return list(path)
    segments = max(len(cut_at(path, horizon_m, position)) - 1, least)
    return list(path[: DEFAULT_LIMITS.public_size(segments) + 1])


def near_answer(
    path: Sequence[tuple[int, int]],
    horizon_m: float,
    position: tuple[int, int] | None = None,
    *,
    segments: int = 2,
) -> tuple[list[tuple[int, int]], int]:
    """Bob's side of a near run: exactly his next ``segments`` segments, whatever lies
    within the horizon -- the run's size, which every listener reads, then shows nothing of
    his path (docs/security.md, D8) -- and how much of the horizon asked they cover, in
    eighths rounded down (:data:`COVER_ALL`: all of it, when the horizon ends within them).
    Alice holds the run's decisions for as far as the cover reaches; the rest of the horizon
    is the full run's.  The caller pads a shorter path to ``segments``."""
    if horizon_m <= 0 or len(path) < 2:
        return list(path), COVER_ALL
    kept = list(path[: segments + 1])
    if len(cut_at(path, horizon_m, position)) <= len(kept):
        return kept, COVER_ALL
    reach = along_m(kept, position)
    return kept, min(COVER_ALL - 1, math.floor(COVER_ALL * reach / horizon_m))


def reached_within(
    path: Sequence[tuple[int, int]],
    first: int,
    position: tuple[int, int] | None,
    distance: float,
) -> set[int]:
    """Indices (``first`` + k) of the segments the drone starts within ``distance`` metres
    along its path from ``position`` (the current segment counts at once)."""
    out = {first}
    travelled = 0.0
    for k, (a, b) in enumerate(itertools.pairwise(path)):
        travelled += distance_m(position if position is not None and k == 0 else a, b)
        if travelled > distance or k + 1 >= len(path) - 1:
            break
        out.add(first + k + 1)
    return out
