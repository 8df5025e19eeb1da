"""Write the in-flight scenarios' missions (``sitl_configs/scenarios/inflight_*.plan``).

Every drone takes off at once and flies a straight multi-leg route at 30 m through a common
crossing point C, so that without the companion they would meet there.  Distances are metres
from C on the local tangent plane; the routes are written as QGroundControl .plan files.
Run from the repository root: ``.venv/bin/python scripts/make_inflight_scenarios.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

from companion.mission.files import format_plan
from companion.mission.items import NAV_LAND, NAV_TAKEOFF, NAV_WAYPOINT, MissionItem
from protocol.tools.cli import write_atomic

C = (47.4000, 8.5450)
ALT = 30.0
OUT = Path(__file__).resolve().parent.parent / "sitl_configs" / "scenarios"


def at(east: float, north: float) -> tuple[float, float]:
    """(lat, lon) ``east``/``north`` metres from C on a 6371 km sphere.  Not
    :mod:`protocol.geo.geodesy`'s ellipsoid, on purpose: the committed .plan files were written
    with this sphere, and ``geodesy.moved`` would move their points by up to 4.5 m (checked:
    inflight_star_east), which changes the replays' timing; switch when regenerating them."""
    lat = C[0] + math.degrees(north / 6_371_000.0)
    lon = C[1] + math.degrees(east / (6_371_000.0 * math.cos(math.radians(C[0]))))
    return lat, lon


def route(name: str, heading_deg: float, stations: list[float], home_back: float = 0.0) -> None:
    """A straight route along ``heading_deg`` (0 = north) through C: waypoints at the given
    distances from C (negative: before C), home ``home_back`` metres before the first.  With
    home at the first station (the default) the take-off climbs over it and the flown path
    has no launch leg of its own: len(stations) segments with the 20 m landing leg, a power
    of two for the protocol's padding (a 60 m launch leg made 5 segments, padded to 8)."""
    ux, uy = math.sin(math.radians(heading_deg)), math.cos(math.radians(heading_deg))

    def point(d: float) -> tuple[float, float]:
        return at(ux * d, uy * d)

    home = point(stations[0] - home_back)

    def item(command: int, d: float, alt: float) -> MissionItem:
        lat, lon = point(d)
        return MissionItem(
            len(items), 3, command, 0, 1, 0.0, 0.0, 0.0, math.nan,
            round(lat * 1e7), round(lon * 1e7), alt,
        )  # fmt: skip

    items = [MissionItem(0, 3, NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0, math.nan, 0, 0, ALT)]
    for d in stations:
        items.append(item(NAV_WAYPOINT, d, ALT))
    items.append(item(NAV_LAND, stations[-1] + 20, 0.0))
    write_atomic(OUT / f"{name}.plan", format_plan(items, [home[0], home[1], 488.0]))


if __name__ == "__main__":
    # Crossing at right angles, 600 m out: they meet about 70 s after take-off.
    route("inflight_east", 90.0, [-600, -250, 250, 600])
    route("inflight_north", 0.0, [-600, -150, 350, 600])
    # Head-on along one line from 1.8 km apart: they meet after about 95 s.
    route("inflight_headon_east", 90.0, [-900, -300, 300, 900])
    route("inflight_headon_west", 270.0, [-900, -500, 100, 900])
    # Three drones through one point, 3 km out (three first contacts share one channel).
    # (1.5 km out was marginal with the crossing-only runs; 2 km with protected-volume runs,
    # about 2.2 times their bytes: one replay in two needed a precaution, at 2.5 km one in three.)
    route("inflight_star_east", 90.0, [-3000, -500, 500, 2000])
    route("inflight_star_north", 0.0, [-3000, -600, 400, 2000])
    route("inflight_star_northeast", 45.0, [-3000, -400, 600, 2000])
    # A long survey-like route (nine 200 m legs) crossed 1.1 km out: an m x n run of 16 x 4.
    # (900 m out, a meeting after ~100 s, was marginal: one run in ~8 needed a precaution.)
    route("inflight_long_east", 90.0, [-1100, -900, -700, -500, -300, -100, 100, 300, 500, 700])
    route("inflight_long_northwest", 300.0, [-1100, -400, 200, 700])
