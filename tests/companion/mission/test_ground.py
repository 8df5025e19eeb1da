"""Ground geometry of paths (companion.mission.ground): points along a leg."""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from companion.mission.ground import along_segment, distance_m
from protocol.geo.geodesy import east_north, moved

A = (473_977_000, 85_456_000)


def _e7(lat: float, lon: float) -> tuple[int, int]:
    return round(lat * 1e7), round(lon * 1e7)


@given(
    north=st.floats(-6000.0, 6000.0),
    east=st.floats(-6000.0, 6000.0),
    share=st.floats(0.01, 0.99),
    plane=st.tuples(st.floats(-5000.0, 5000.0), st.floats(-5000.0, 5000.0)),
)
def test_a_point_along_a_leg_lies_on_it_on_a_nearby_tangent_plane(
    north: float, east: float, share: float, plane: tuple[float, float]
) -> None:
    """The point ``share`` of the way along a leg of up to 8.5 km is that share of its length
    from the start and within 2 cm of the straight line between the leg's ends as a run's
    grid sees them (a tangent plane up to 7 km away); a point halfway in latitude and
    longitude is half a metre off a 5 km leg."""
    b = _e7(*moved(A[0] / 1e7, A[1] / 1e7, north, east))
    if distance_m(A, b) < 10.0:
        return
    p = along_segment(A, b, share)
    assert abs(distance_m(A, p) - share * distance_m(A, b)) <= 0.02
    ref = moved(A[0] / 1e7, A[1] / 1e7, *plane)
    pa, pb, pp = (east_north(*ref, q[0] / 1e7, q[1] / 1e7) for q in (A, b, p))
    dx, dy = pb[0] - pa[0], pb[1] - pa[1]
    off = abs((pp[0] - pa[0]) * dy - (pp[1] - pa[1]) * dx) / math.hypot(dx, dy)
    assert off <= 0.02


def test_the_ends_are_the_leg_s_own_vertices() -> None:
    b = _e7(*moved(A[0] / 1e7, A[1] / 1e7, 5000.0, 0.0))
    assert along_segment(A, b, 0.0) == A and along_segment(A, b, 1.0) == b
