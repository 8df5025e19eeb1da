"""Protected volumes on the integer grid: the conflict predicate beyond the paper's crossing.

A segment, as flown, occupies

* its ground track widened by the horizontal separation r (a *capsule*: every point within r
  of the segment),
* the altitude band it flies (lowest to highest altitude along it, ramps included), and
* the time window in which it is flown (already widened by its owner's own uncertainty).

Two segments *conflict* when their capsules meet (the segments come within r of each other),
their bands come within the vertical separation v of each other, and their windows overlap.
Everything is exact in integers (``../shared/notes/separation.md``, the exact degree-2 test):

* dist(AB, CD) <= r  iff  AB and CD cross (:func:`protocol.geo.geometry.segments_intersect`), or
  one of the four end points lies in the other segment's capsule;
* X lies within r of [U, V] (d = V - U, w = X - U, L = d.d, t = w.d, c = cross(d, w)) iff
  |X - U|^2 <= r^2, or |X - V|^2 <= r^2, or (L > 0 and 0 <= t <= L and |c| <= R) with
  R = floor(sqrt(r^2 L)) -- the owner of [U, V] computes R alone, so every compared value
  stays of degree 2 in the coordinates (:func:`slab_radius`);
* bands [a, b] and [c, d] come within v iff a - v <= d and c - v <= b; windows overlap iff
  a <= d and c <= b (closed: touching counts).

With r = 0, no bands and no windows this is exactly the crossing test.  The private protocol
computes :func:`route_hits` (:mod:`protocol.circuits.paths` for the circuit); the paper suite
keeps the paper's predicate (the crossing only).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.errors import InputRangeError, RemoteProtocolError
from protocol.geo.geometry import Point, orient, segments_intersect
from protocol.wire.encoding import Reader

Interval = tuple[int, int]  # closed, low <= high

MAX_SEPARATION = 0xFFFF  # grid units (at the default 0.5 m: 32 km)
MAX_Z_RANGE = 1 << 24  # grid units: bands within +-Z (at 0.5 m: 8400 km, any altitude)
MAX_T_RANGE = 1 << 24  # seconds: windows within [0, T] of the epoch (194 days)


@dataclass(frozen=True, slots=True)
class Separation:
    """Public separation minima in grid units: horizontal r (the capsule's radius) and
    vertical v (how close two altitude bands may come).  Both parties' settings are public;
    a run uses the larger of each (:meth:`widest`)."""

    horizontal: int = 0
    vertical: int = 0

    def __post_init__(self) -> None:
        for name, value in (("horizontal", self.horizontal), ("vertical", self.vertical)):
            if not 0 <= value <= MAX_SEPARATION:
                raise InputRangeError(f"{name} separation {value} outside 0..{MAX_SEPARATION}")

    def widest(self, other: Separation) -> Separation:
        return Separation(
            max(self.horizontal, other.horizontal), max(self.vertical, other.vertical)
        )


SEPARATION_SIZE = 4  # horizontal u16, vertical u16


def write_separation(separation: Separation) -> bytes:
    return separation.horizontal.to_bytes(2, "big") + separation.vertical.to_bytes(2, "big")


def read_separation(reader: Reader) -> Separation:
    """Separation minima as a peer sent them (both fields u16: always in range)."""
    return Separation(reader.uint(2), reader.uint(2))


@dataclass(frozen=True, slots=True)
class VolumeSpec:
    """The public volume parameters of a run, in Alice's hello: her separation minima; the
    altitude range Z (every band value is clamped to [-Z, Z], in grid units; 0: the run
    compares no altitudes); the time range T (every window value is clamped to [0, T],
    seconds after ``epoch_s``; 0: no times) and the epoch (Unix seconds, for the peer to put
    his windows on the same clock).  All zero: the paper's crossing test."""

    separation: Separation = Separation()
    z_range: int = 0
    t_range: int = 0
    epoch_s: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.z_range <= MAX_Z_RANGE:
            raise InputRangeError(f"altitude range {self.z_range} outside 0..{MAX_Z_RANGE}")
        if not 0 <= self.t_range <= MAX_T_RANGE:
            raise InputRangeError(f"time range {self.t_range} s outside 0..{MAX_T_RANGE}")
        if not 0 <= self.epoch_s < 1 << 32:
            raise InputRangeError(f"epoch {self.epoch_s} outside 32 bits")

    @property
    def bands(self) -> bool:
        return self.z_range > 0

    @property
    def windows(self) -> bool:
        return self.t_range > 0

    def to_bytes(self) -> bytes:
        """``0`` for the crossing test, else ``1`` | r u16 | v u16 | Z u32 | T u32 | epoch u32."""
        if self == VolumeSpec():
            return b"\x00"
        return (
            b"\x01"
            + write_separation(self.separation)
            + b"".join(f.to_bytes(4, "big") for f in (self.z_range, self.t_range, self.epoch_s))
        )

    @classmethod
    def read(cls, reader: Reader) -> VolumeSpec:
        kind = reader.uint(1)
        if kind == 0:
            return cls()
        if kind != 1:
            raise RemoteProtocolError(f"unknown volume parameters kind {kind}")
        separation = read_separation(reader)
        z, t, epoch = reader.uint(4), reader.uint(4), reader.uint(4)
        try:
            return cls(separation, z, t, epoch)
        except InputRangeError as exc:
            raise RemoteProtocolError(f"peer's volume parameters refused: {exc}") from exc

    def band_bits(self, vertical: int) -> int:
        """l of a band comparison, b_hi - a_lo + v in [-2Z, 2Z + v]."""
        return max(1, (2 * self.z_range + vertical).bit_length())

    def window_bits(self) -> int:
        """l of a window comparison, b_hi - a_lo in [-T, T]."""
        return max(1, self.t_range.bit_length())

    def clamp_band(self, band: Interval | None) -> Interval:
        """A band within [-Z, Z] (none: every altitude)."""
        z = self.z_range
        if band is None:
            return -z, z
        return max(-z, min(z, band[0])), max(-z, min(z, band[1]))

    def clamp(self, route: Route) -> Route:
        """The route as a run compares it: its bands and windows clamped (:meth:`clamp_band`,
        :meth:`clamp_window`); a run without bands (windows) drops them."""
        bands = route.bands if self.bands else None
        windows = route.windows if self.windows else None
        return Route(
            route.points,
            None if bands is None else tuple(self.clamp_band(b) for b in bands),
            None if windows is None else tuple(self.clamp_window(w) for w in windows),
        )

    def clamp_window(self, window: Interval | None) -> Interval:
        """A window within [0, T] (none: all of it)."""
        t = self.t_range
        if window is None:
            return 0, t
        return max(0, min(t, window[0])), max(0, min(t, window[1]))


NO_SEPARATION = Separation()
CROSSING = VolumeSpec()  # no separation, no altitudes, no times: the paper's crossing test


@dataclass(frozen=True, slots=True)
class Route:
    """A path as flown: its points on the grid and, per segment, the altitude band (grid
    units, e.g. AMSL) and the time window (seconds from a common epoch) -- each optional.
    A route without bands (windows) conflicts at any altitude (time)."""

    points: tuple[Point, ...]
    bands: tuple[Interval, ...] | None = None
    windows: tuple[Interval, ...] | None = None

    def __post_init__(self) -> None:
        if len(self.points) < 2:
            raise InputRangeError("a path needs at least two points")
        for name, intervals in (("band", self.bands), ("window", self.windows)):
            if intervals is None:
                continue
            if len(intervals) != self.segments:
                raise InputRangeError(
                    f"{len(intervals)} {name}s for {self.segments} segments (one per segment)"
                )
            for low, high in intervals:
                if low > high:
                    raise InputRangeError(f"{name} [{low}, {high}] is empty")

    @property
    def segments(self) -> int:
        return len(self.points) - 1

    def band(self, k: int) -> Interval | None:
        return None if self.bands is None else self.bands[k]

    def window(self, k: int) -> Interval | None:
        return None if self.windows is None else self.windows[k]


def slab_radius(u: Point, v: Point, r: int) -> int:
    """R = floor(sqrt(r^2 L)) for the segment [u, v] (L = |v - u|^2): a point X at signed
    cross(v - u, X - u) = c lies within r of the segment's line iff |c| <= R.  -1 for a
    zero-length segment (no slab: only the discs at its end)."""
    length = (v[0] - u[0]) ** 2 + (v[1] - u[1]) ** 2
    return math.isqrt(r * r * length) if length else -1


def dist2(p: Point, q: Point) -> int:
    return (p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2


def point_near_segment(x: Point, u: Point, v: Point, r: int) -> bool:
    """X lies within r of the closed segment [u, v] (the integer form of the module)."""
    if dist2(x, u) <= r * r or dist2(x, v) <= r * r:
        return True
    dx, dy = v[0] - u[0], v[1] - u[1]
    length = dx * dx + dy * dy
    t = (x[0] - u[0]) * dx + (x[1] - u[1]) * dy
    return length > 0 and 0 <= t <= length and abs(orient(u, v, x)) <= slab_radius(u, v, r)


def segments_near(a: Point, b: Point, c: Point, d: Point, r: int) -> bool:
    """The closed segments [a, b] and [c, d] come within r of each other."""
    return (
        segments_intersect(a, b, c, d)
        or point_near_segment(c, a, b, r)
        or point_near_segment(d, a, b, r)
        or point_near_segment(a, c, d, r)
        or point_near_segment(b, c, d, r)
    )


def bands_near(first: Interval | None, second: Interval | None, v: int) -> bool:
    """Two altitude bands come within v (a missing band is every altitude)."""
    if first is None or second is None:
        return True
    return first[0] - v <= second[1] and second[0] - v <= first[1]


def windows_meet(first: Interval | None, second: Interval | None) -> bool:
    """Two time windows overlap (a missing window is all of time)."""
    if first is None or second is None:
        return True
    return first[0] <= second[1] and second[0] <= first[1]


def volumes_meet(alice: Route, i: int, bob: Route, k: int, separation: Separation) -> bool:
    """Alice's segment i and Bob's segment k conflict."""
    a, b = alice.points[i], alice.points[i + 1]
    c, d = bob.points[k], bob.points[k + 1]
    return (
        windows_meet(alice.window(i), bob.window(k))
        and bands_near(alice.band(i), bob.band(k), separation.vertical)
        and segments_near(a, b, c, d, separation.horizontal)
    )


def route_hits(alice: Route, bob: Route, separation: Separation) -> list[bool]:
    """For each of Alice's segments: does its volume meet any of Bob's?  (The reference the
    private protocol must agree with.)"""
    return [
        any(volumes_meet(alice, i, bob, k, separation) for k in range(bob.segments))
        for i in range(alice.segments)
    ]


def as_route(path: Sequence[Point] | Route) -> Route:
    return path if isinstance(path, Route) else Route(tuple(path))


def pad_route(route: Route, segments: int) -> Route:
    """The route in ``segments`` segments: the last vertex repeated (a zero-length segment at
    an existing vertex, with the last segment's band and window, changes no answer)."""
    extra = segments - route.segments

    def pad(intervals: tuple[Interval, ...] | None) -> tuple[Interval, ...] | None:
        return None if intervals is None else intervals + (intervals[-1],) * extra

    points = route.points + (route.points[-1],) * extra
    return Route(points, pad(route.bands), pad(route.windows))
