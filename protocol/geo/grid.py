"""The common integer grid: WGS84 (MAVLink degE7) to a local tangent plane, and its range.

Both drones project their waypoints onto the same grid: an east-north plane tangent to the
WGS84 ellipsoid at a public reference point carried in the protocol's first message, with a
public resolution (default 0.5 m).  Every grid coordinate must satisfy |x|, |y| <= R, the public
*range*; the comparison bit length follows from it (:func:`comparison_bits`), so orientation
values can never overflow the comparison.  Anything outside is refused with
:class:`InputRangeError`.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.errors import InputRangeError, RemoteProtocolError
from protocol.geo.geodesy import east_north
from protocol.geo.geometry import Point

MAX_RANGE = 1 << 28  # keeps l <= 61 bits
DEFAULT_RESOLUTION_MM = 500
DEFAULT_RADIUS_M = 5000


class GridKind(enum.IntEnum):
    PLANE = 0  # inputs already are integer grid points (paper's data, tests)
    GEO = 1  # inputs are WGS84 degE7, projected at the reference point


def comparison_bits(range_: int) -> int:
    """l with 2^l > 16 R^2 + 1: every orientation or projection value v and threshold
    theta in the protocol satisfy -2^l <= v - theta < 2^l (see ``geometry``)."""
    return (16 * range_ * range_ + 1).bit_length()


def check_degE7(lat: int, lon: int) -> None:
    if not -900_000_000 <= lat <= 900_000_000:
        raise InputRangeError(f"latitude {lat} degE7 outside [-90, 90] degrees")
    if not -1_800_000_000 <= lon <= 1_800_000_000:
        raise InputRangeError(f"longitude {lon} degE7 outside [-180, 180] degrees")


@dataclass(frozen=True, slots=True)
class GridSpec:
    """Public grid parameters both parties use; encoded in the first message."""

    kind: GridKind = GridKind.PLANE
    range: int = 1 << 12
    ref_lat_e7: int = 0
    ref_lon_e7: int = 0
    resolution_mm: int = DEFAULT_RESOLUTION_MM

    def __post_init__(self) -> None:
        if not 1 <= self.range <= MAX_RANGE:
            raise InputRangeError(f"grid range {self.range} outside 1..{MAX_RANGE}")
        if not 1 <= self.resolution_mm <= 1_000_000:
            raise InputRangeError(f"resolution {self.resolution_mm} mm outside 1..1000000")
        check_degE7(self.ref_lat_e7, self.ref_lon_e7)

    @classmethod
    def geo(
        cls,
        ref_lat_e7: int,
        ref_lon_e7: int,
        *,
        resolution_mm: int = DEFAULT_RESOLUTION_MM,
        radius_m: float = DEFAULT_RADIUS_M,
    ) -> GridSpec:
        """A tangent-plane grid covering ``radius_m`` around the reference point."""
        range_ = max(1, math.ceil(radius_m * 1000 / resolution_mm))
        return cls(GridKind.GEO, range_, ref_lat_e7, ref_lon_e7, resolution_mm)

    @property
    def l(self) -> int:  # noqa: E743 (the paper's name)
        return comparison_bits(self.range)

    @property
    def radius_m(self) -> float:
        """How far the box reaches from the reference point (geographic grids)."""
        return self.range * self.resolution_mm / 1000

    @property
    def span(self) -> int:
        """Bound on any coordinate difference."""
        return 2 * self.range

    def check_points(self, points: Sequence[Point]) -> None:
        for x, y in points:
            if abs(x) > self.range or abs(y) > self.range:
                raise InputRangeError(f"point ({x}, {y}) outside the grid range +-{self.range}")

    def project(self, lat_e7: int, lon_e7: int, *, checked: bool = True) -> Point:
        """East/north grid cell of a WGS84 point (altitude 0); refused outside the range
        unless ``checked`` is False (Bob cuts his path to the box himself)."""
        if self.kind is not GridKind.GEO:
            raise InputRangeError("this grid takes plane coordinates, not latitude/longitude")
        check_degE7(lat_e7, lon_e7)
        east, north = east_north(
            self.ref_lat_e7 / 1e7, self.ref_lon_e7 / 1e7, lat_e7 / 1e7, lon_e7 / 1e7
        )
        scale = 1000 / self.resolution_mm
        point = (round(east * scale), round(north * scale))
        if checked:
            self.check_points([point])
        return point

    def project_path(
        self, points: Sequence[tuple[int, int]], *, checked: bool = True
    ) -> tuple[Point, ...]:
        return tuple(self.project(lat, lon, checked=checked) for lat, lon in points)

    # ----------------------------------------------------------------- wire encoding

    SIZE = 1 + 4 + 4 + 4 + 4

    def to_bytes(self) -> bytes:
        return (
            bytes([self.kind])
            + self.range.to_bytes(4, "big")
            + self.ref_lat_e7.to_bytes(4, "big", signed=True)
            + self.ref_lon_e7.to_bytes(4, "big", signed=True)
            + self.resolution_mm.to_bytes(4, "big")
        )

    @classmethod
    def from_bytes(cls, data: bytes) -> GridSpec:
        if len(data) != cls.SIZE:
            raise RemoteProtocolError("grid specification has the wrong size")
        try:
            kind = GridKind(data[0])
        except ValueError as exc:
            raise RemoteProtocolError(f"unknown grid kind {data[0]}") from exc
        try:
            return cls(
                kind,
                int.from_bytes(data[1:5], "big"),
                int.from_bytes(data[5:9], "big", signed=True),
                int.from_bytes(data[9:13], "big", signed=True),
                int.from_bytes(data[13:17], "big"),
            )
        except InputRangeError as exc:
            raise RemoteProtocolError(f"peer's grid refused: {exc}") from exc
