"""The fleet simulation (companion.sim.city), the radio range of the simulated channel and
the busy-sky report's screen of far pairs."""

from __future__ import annotations

import math
import random

import pytest

from companion.mission.items import NAV_LAND, NAV_TAKEOFF
from companion.sim.city import (
    BANDS,
    WARM_UP_S,
    CitySpec,
    city_json,
    city_scenario,
    format_city,
    run_city,
)
from companion.sim.medium import Channel
from companion.sim.metrics import Screen, closest
from protocol.geo.geodesy import ground_offset


def _sent(channel: Channel, src: int, start: float) -> list[tuple[int, float, bytes]]:
    return channel.end(channel.begin(src, b"frame", start, 0.1))


def test_radios_out_of_range_neither_hear_nor_disturb_each_other() -> None:
    # nodes on a line: 1 -- 2 -- 3, each hears its neighbour only
    where = {1: 0.0, 2: 1.0, 3: 2.0}
    channel = Channel(reach=lambda a, b: abs(where[a] - where[b]) <= 1.0)
    channel.nodes.update(where)
    assert [node for node, *_ in _sent(channel, 1, 0.0)] == [2]
    assert channel.busy(2, 0.5) is False and channel.busy(3, 0.5) is False
    # 1 and 3 send at once: 2 hears both (a collision there), nobody else hears anything
    one = channel.begin(1, b"a", 1.0, 0.1)
    three = channel.begin(3, b"b", 1.0, 0.1)
    assert channel.busy(2, 1.05) and not channel.busy(1, 1.05)  # 3 is out of 1's reach
    assert channel.end(one) == [] and channel.end(three) == []
    assert channel.stats.collisions == 2
    # without a reach, everybody hears everybody
    plain = Channel()
    plain.nodes.update(where)
    assert sorted(node for node, *_ in _sent(plain, 1, 0.0)) == [2, 3]


def test_the_screen_agrees_with_the_exact_closest_approach() -> None:
    rng = random.Random(5)
    ref = (47.39, 8.53)
    for _ in range(20):
        tracks = []
        for _ in range(2):
            lat, lon = ref[0] + rng.uniform(-0.02, 0.02), ref[1] + rng.uniform(-0.03, 0.03)
            dlat, dlon = rng.uniform(-1e-5, 1e-5), rng.uniform(-1e-5, 1e-5)
            tracks.append(
                [
                    (t / 5, lat + dlat * t, lon + dlon * t, 480.0 + rng.uniform(0, 30))
                    for t in range(3000)
                ]
            )
        exact = closest(tracks[0], tracks[1])[0]
        coarse = Screen(ref).closest(tracks[0], tracks[1])
        # whole seconds only: the drones close at most ~2.5 m/s each here, plus the altitudes'
        # own jitter between the samples
        assert exact - 1.0 <= coarse <= exact + 40.0


def test_a_city_is_the_same_sky_for_the_same_seed() -> None:
    spec = CitySpec(drones=12, hours=0.5, area_km=4.0, seed=3)
    a, b = city_scenario(spec), city_scenario(spec)
    assert [(d.home, d.mission, d.takeoff_delay_s) for d in a.drones] == [
        (d.home, d.mission, d.takeoff_delay_s) for d in b.drones
    ]
    assert city_scenario(CitySpec(drones=12, hours=0.5, seed=4)).drones != a.drones
    assert a.radio_range_m == 3000.0
    for d in a.drones:
        assert d.mission[0].command == NAV_TAKEOFF and d.mission[-1].command == NAV_LAND
        assert d.companion_start_s == pytest.approx(d.takeoff_delay_s - WARM_UP_S, abs=0.1)
        assert d.companion_off_landed and not d.hold_for_comparisons
        assert 0 < d.takeoff_delay_s <= 0.5 * 3600
        north, east = ground_offset(47.39, 8.53, d.home[0], d.home[1])
        assert max(abs(north), abs(east)) <= 2000.5
    with pytest.raises(ValueError, match="drones"):
        CitySpec(drones=1)


@pytest.mark.slow
def test_a_small_city_flies_and_is_summed_up() -> None:
    spec = CitySpec(drones=5, hours=0.15, area_km=2.0, range_km=1.5, seed=2)
    city = run_city(spec)
    assert city.replay.finished  # every mission flown
    report = city.replay
    assert len(report.drones) == 5 and len(report.pairs) == 10
    # each drone's radio was on, and off once landed: it sent beacons, and it heard the
    # others in range
    assert all(d.bytes_sent > 0 for d in report.drones)
    assert 0.2 < city.drone_hours < 5 * 0.15
    assert sum(b.drones for b in city.bands) == 5
    assert len(city.bands) == len(BANDS)
    # a 2 km square and a 1.5 km range: most drones hear another while both are airborne
    assert any(n > 0 for n in city.in_range.values())
    assert all(0.0 <= load < 1.0 for load in city.load.values())
    assert any(load > 0.0 for load in city.load.values())
    text = format_city(city)
    assert "drone-hours airborne" in text and "in range" in text
    summary = city_json(city)
    assert summary["finished"] is True and len(summary["bands"]) == len(BANDS)  # type: ignore[arg-type]
    assert math.isclose(float(summary["drone_hours"]), city.drone_hours)  # type: ignore[arg-type]
