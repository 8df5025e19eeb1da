"""How often our beacons go (companion.neighbours.sender): the cadence per link profile, and
the sender's loop."""

from __future__ import annotations

import contextlib
import itertools
from typing import cast

import pytest

from companion.auth.beacon_keys import BeaconKeys
from companion.auth.session import Identity
from companion.mission.levels import Slots
from companion.neighbours.beacon import BeaconKind
from companion.neighbours.beacon_airtime import beacon_interval
from companion.neighbours.peers import FRESH_S
from companion.neighbours.registry import Neighbours
from companion.neighbours.sender import BeaconSender, Cadence, OwnBeacon
from companion.radio import PROFILES
from companion.radio.clock import Clock
from companion.radio.endpoint import LinkEndpoint
from companion.sim.virtual_time import run_simulated
from companion.state import StateStore
from protocol.messages import Suite


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


def test_a_drone_landed_with_its_mission_flown_beacons_less_yet_stays_heard(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Five minutes of beacons, jittered: ~30 a drone with something to fly, ~12 once it
    has landed with its mission flown -- and the longest gap, a deferral of half an
    interval included, stays under the silence after which peers take it for a drone
    fallen silent (or drop it from their beacons' tags)."""
    cadence = Cadence.of(PROFILES["us915-sf7"], 10.0)
    assert cadence.interval_s < cadence.done_s
    assert 1.3 * cadence.done_s + 0.5 * cadence.interval_s < cadence.silence_s

    class Endpoint:
        def __init__(self) -> None:
            self.clock = Clock()
            self.sent: list[float] = []

        async def beacon(self, payload: bytes) -> None:
            self.sent.append(self.clock.now())

    def sent_in_five_minutes(done: bool) -> list[float]:
        async def main() -> list[float]:
            endpoint = Endpoint()
            sender = BeaconSender(
                1,
                cast(LinkEndpoint, endpoint),
                cast(Identity, None),
                cast(BeaconKeys, None),
                b"",
                cast(StateStore, None),
                cast(Neighbours, None),
                cadence,
            )
            own = OwnBeacon(0, 0, 0, True, Suite.COMPACT, 0, Slots(), 1, done)
            monkeypatch.setattr(sender, "_position", lambda _: (b"beacon", BeaconKind.TAGGED))
            with contextlib.suppress(TimeoutError):
                await endpoint.clock.wait_for(sender.positions(lambda: own, lambda: False), 300.0)
            return endpoint.sent

        return run_simulated(main())

    flying, landed = sent_in_five_minutes(False), sent_in_five_minutes(True)
    assert 23 <= len(flying) <= 43 and 9 <= len(landed) <= 17
    assert max(b - a for a, b in itertools.pairwise(landed)) <= 1.3 * cadence.done_s + 1e-6
