"""One model of the Earth for the whole project: the WGS84 ellipsoid and its local tangent
plane (east, north, up) at a reference point.

The protocol's grid (:mod:`protocol.geo.grid`) projects with it; the companion measures distances,
moves points (loiter rings, look-ahead cuts) and the mock autopilot flies with it, so a metre
is the same metre everywhere (a sphere of radius 6371 km differs from the ellipsoid by up to
0.3 %, 3 m per km).  Pure functions of degrees; no I/O.
"""

from __future__ import annotations

import functools
import math

A = 6378137.0  # WGS84 semi-major axis (m)
F = 1 / 298.257223563  # flattening
E2 = F * (2 - F)  # first eccentricity squared


@functools.lru_cache(maxsize=4096)
def ecef(lat_deg: float, lon_deg: float, height_m: float = 0.0) -> tuple[float, float, float]:
    """Earth-centred, Earth-fixed coordinates (m) of a WGS84 point (remembered for the last
    few thousand points: a flight asks for the same waypoints at every step)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n = A / math.sqrt(1 - E2 * math.sin(lat) ** 2)
    return (
        (n + height_m) * math.cos(lat) * math.cos(lon),
        (n + height_m) * math.cos(lat) * math.sin(lon),
        (n * (1 - E2) + height_m) * math.sin(lat),
    )


def east_north(lat0: float, lon0: float, lat1: float, lon1: float) -> tuple[float, float]:
    """(east, north) metres of point 1 on the tangent plane at point 0 (both at height 0)."""
    x, y, z = ecef(lat1, lon1)
    x0, y0, z0, sin_lam, cos_lam, sin_phi, cos_phi = _plane(lat0, lon0)
    dx, dy, dz = x - x0, y - y0, z - z0
    east = -sin_lam * dx + cos_lam * dy
    north = -sin_phi * cos_lam * dx - sin_phi * sin_lam * dy + cos_phi * dz
    return east, north


@functools.lru_cache(maxsize=4096)
def _plane(lat0: float, lon0: float) -> tuple[float, float, float, float, float, float, float]:
    """The tangent plane at a point: its ECEF origin and the sines and cosines of its
    longitude and latitude."""
    phi, lam = math.radians(lat0), math.radians(lon0)
    return (*ecef(lat0, lon0), math.sin(lam), math.cos(lam), math.sin(phi), math.cos(phi))


def ground_offset(lat0: float, lon0: float, lat1: float, lon1: float) -> tuple[float, float]:
    """(north, east) metres from point 0 to point 1 (degrees)."""
    east, north = east_north(lat0, lon0, lat1, lon1)
    return north, east


def metres_per_degree(lat_deg: float) -> tuple[float, float]:
    """(north, east) metres per degree of latitude and of longitude at ``lat_deg`` (the
    meridian and prime-vertical radii of curvature)."""
    s2 = math.sin(math.radians(lat_deg)) ** 2
    meridian = A * (1 - E2) / (1 - E2 * s2) ** 1.5
    prime = A / math.sqrt(1 - E2 * s2)
    return meridian * math.pi / 180, prime * math.cos(math.radians(lat_deg)) * math.pi / 180


def moved(lat_deg: float, lon_deg: float, north_m: float, east_m: float) -> tuple[float, float]:
    """The point whose :func:`ground_offset` from (lat, lon) is (``north_m``, ``east_m``): the
    exact inverse of the tangent-plane projection (found by a few corrections of the
    latitude/longitude step; within 10 km it converges to well under a millimetre)."""
    per_lat, per_lon = metres_per_degree(lat_deg)
    lat, lon = lat_deg + north_m / per_lat, lon_deg + east_m / per_lon
    for _ in range(4):
        north, east = ground_offset(lat_deg, lon_deg, lat, lon)
        d_north, d_east = north_m - north, east_m - east
        if abs(d_north) < 1e-6 and abs(d_east) < 1e-6:
            break
        per_lat, per_lon = metres_per_degree(lat)
        lat, lon = lat + d_north / per_lat, lon + d_east / per_lon
    return lat, lon
