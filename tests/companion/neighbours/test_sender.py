"""How often our beacons go (companion.neighbours.sender.Cadence), per link profile."""

from __future__ import annotations

import pytest

from companion.neighbours.beacon_airtime import beacon_interval
from companion.neighbours.peers import FRESH_S
from companion.neighbours.sender import Cadence
from companion.radio import PROFILES


@pytest.mark.parametrize("name", ["us915-sf7", "eu868-sf7", "eu868-sf9"])
def test_cadence_follows_the_profile_and_the_configured_interval(name: str) -> None:
    cadence = Cadence.of(PROFILES[name], 10.0)
    interval = beacon_interval(PROFILES[name], 10.0)
    assert cadence.interval_s == interval >= 10.0  # stretched under a duty cycle
    assert cadence.signed_every_s == max(300.0, 30 * interval)
    assert cadence.asked_every_s == 5.0  # half the configured interval, not the stretched one
    assert cadence.silence_s == 4 * interval + FRESH_S
    if PROFILES[name].duty_cycle is None:
        assert interval == 10.0
