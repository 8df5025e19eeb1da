"""What a replay measures of a pair: intrusions in the air, and whether a drone flew
differently from its baseline at all (:mod:`companion.sim.metrics`)."""

from __future__ import annotations

import math

from companion.sim.metrics import DEVIATED_M, closest, deviation, intrusion
from companion.sim.vehicles import Track
from protocol.geo.geodesy import moved

HOME = (47.0, 8.0)
GROUND = 400.0  # AMSL


def _track(
    north_m: float,
    east_m: float,
    alt: float,
    *,
    speed_m_s: float = 0.0,
    seconds: float = 60.0,
    late_s: float = 0.0,
    rate_hz: float = 5.0,
) -> Track:
    """A track north-bound at ``speed_m_s`` from (north, east) of HOME, ``late_s`` behind."""
    out: Track = []
    for k in range(int(seconds * rate_hz) + 1):
        t = k / rate_hz
        lat, lon = moved(*HOME, north_m + speed_m_s * max(t - late_s, 0.0), east_m)
        out.append((t, lat, lon, alt))
    return out


def test_two_drones_parked_side_by_side_are_no_conflict() -> None:
    """Pads 5 m apart: inside a 15 m volume for the whole minute, but not in the air."""
    a, b = _track(0, 0, GROUND), _track(0, 5, GROUND)
    assert intrusion(a, b, 15, 10)[0] == 60.0  # counted on the ground
    assert intrusion(a, b, 15, 10, grounds=(GROUND, GROUND)) == (0.0, math.inf)


def test_an_intrusion_in_the_air_counts_beside_a_drone_on_the_ground() -> None:
    """One parked, one hovering 3 m over its own pad 5 m away: no traffic; both in the air,
    it is."""
    parked, hovering = _track(0, 0, GROUND), _track(0, 5, GROUND + 3)
    assert intrusion(parked, hovering, 15, 10, grounds=(GROUND, GROUND))[0] == 0.0
    lifted = _track(0, 0, GROUND + 1)
    inside, first = intrusion(lifted, hovering, 15, 10, grounds=(GROUND, GROUND))
    assert inside == 60.0 and first == 0.0


def test_a_drone_late_by_the_simulations_step_has_not_flown_differently() -> None:
    """A take-off a step late (0.2 s at 8 m/s) is the simulation's timing, not an action; a
    raise of one level (10 m) or a 10 s hold is."""
    baseline = _track(0, 0, GROUND + 30, speed_m_s=8.0)
    late = _track(0, 0, GROUND + 30, speed_m_s=8.0, late_s=0.2)
    assert 1.0 < deviation(late, baseline) < DEVIATED_M
    raised = _track(0, 0, GROUND + 40, speed_m_s=8.0)
    assert deviation(raised, baseline) == 10.0 > DEVIATED_M
    held = _track(0, 0, GROUND + 30, speed_m_s=8.0, late_s=10.0)
    assert deviation(held, baseline) > DEVIATED_M


def test_closest_approach_is_the_3d_distance_at_the_same_time() -> None:
    """Head-on along one line, 12 m apart vertically: they meet at 30 s, 12 m apart."""
    up = _track(-240, 0, GROUND + 30, speed_m_s=8.0)
    down = [(t, *moved(*HOME, 240 - 8.0 * t, 0.0), GROUND + 42) for t, *_ in up]
    distance, when, _, _ = closest(up, down)
    assert math.isclose(distance, 12.0, abs_tol=1e-3) and when == 30.0
