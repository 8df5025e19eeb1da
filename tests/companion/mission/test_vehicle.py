"""The vehicle as its telemetry tells it (companion.mission.vehicle)."""

from __future__ import annotations

import pytest

from companion.mission.vehicle import VehicleState


def test_positions_give_speed_climb_and_the_take_off() -> None:
    v = VehicleState()
    assert v.on_ground and v.here() is None
    assert not v.moved(47.0, 8.0, 500.0, 0.0, now=0.0)  # on the ground
    assert v.moved(47.0, 8.0, 502.0, 2.0, now=0.5)  # it left the ground
    assert v.has_flown and not v.on_ground and v.here() == (470000000, 80000000)
    assert not v.moved(47.0001, 8.0, 504.0, 4.0, now=1.0)  # 11.1 m north a second later
    assert v.speed_m_s == pytest.approx(0.5 * 11.12, rel=0.01)  # smoothed from 0
    assert v.climb_m_s == pytest.approx(4.0)
    assert v.position_at == 1.0


def test_arming_low_is_a_departure() -> None:
    v = VehicleState()
    assert v.arming(True) and v.has_flown and not v.on_ground  # armed below 1 m: leaving
    assert not v.arming(True)  # (once)
    v.moved(47.0, 8.0, 530.0, 30.0, now=0.0)
    v.arming(False)
    assert not v.on_ground  # disarmed in the air is still flight
