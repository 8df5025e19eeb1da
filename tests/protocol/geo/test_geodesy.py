"""One Earth model: WGS84 tangent plane, its inverse, and the grid built on it."""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from protocol.geo.geodesy import A, ground_offset, metres_per_degree, moved
from protocol.geo.grid import GridSpec

lats = st.floats(-80, 80)
lons = st.floats(-179, 179)
metres = st.floats(-10_000, 10_000)


@given(lats, lons, metres, metres)
def test_moved_is_the_inverse_of_ground_offset(lat: float, lon: float, n: float, e: float) -> None:
    """Within 10 km, moving a point and measuring the offset back agrees to a millimetre:
    the companion's moved points (loiter rings, the mock's flight) land where the grid and
    every distance say."""
    lat1, lon1 = moved(lat, lon, n, e)
    north, east = ground_offset(lat, lon, lat1, lon1)
    assert abs(north - n) <= 1e-3 and abs(east - e) <= 1e-3


def test_the_ellipsoid_not_a_sphere() -> None:
    """A degree of latitude is 110.57 km at the equator and 111.69 km at the poles (WGS84);
    a 6371 km sphere would say 111.19 km everywhere."""
    assert abs(metres_per_degree(0.0)[0] - 110_574) < 1
    assert abs(metres_per_degree(89.999)[0] - 111_694) < 1
    assert abs(metres_per_degree(0.0)[1] - A * math.pi / 180) < 1e-6


@given(metres, metres)
def test_the_grid_projects_with_the_same_model(n: float, e: float) -> None:
    """The protocol's grid cell of a point is its ground offset in resolution steps."""
    lat0, lon0 = 47.397742, 8.545594
    lat1, lon1 = moved(lat0, lon0, n, e)
    grid = GridSpec.geo(round(lat0 * 1e7), round(lon0 * 1e7), resolution_mm=1000, radius_m=20_000)
    x, y = grid.project(round(lat1 * 1e7), round(lon1 * 1e7))
    north, east = ground_offset(
        round(lat0 * 1e7) / 1e7,
        round(lon0 * 1e7) / 1e7,
        round(lat1 * 1e7) / 1e7,
        round(lon1 * 1e7) / 1e7,
    )
    assert (x, y) == (round(east), round(north))
