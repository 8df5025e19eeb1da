"""Write the busy-sky scenarios (``sitl_configs/scenarios/busy_*.plan`` and ``busy_*.toml``).

Many drones in radio range, all in flight, on one shared radio (issue 29): six drones through
one point at once, ten drones over one neighbourhood with one real conflict, four drones
through one point on EU868's 10 % sub-band.  Same conventions as
``make_separation_scenarios.py`` (30 m above a home at 488 m, metres east/north of a common
point C).  Run from the repository root: ``.venv/bin/python scripts/make_busy_sky_scenarios.py``.
"""

from __future__ import annotations

import math

from make_separation_scenarios import OUT, mission, scenario


def through_centre(name: str, heading_deg: float, stations: list[float]) -> None:
    """A straight route along ``heading_deg`` (0 = north) through C, waypoints at the given
    distances from C (negative: before it)."""
    ux, uy = math.sin(math.radians(heading_deg)), math.cos(math.radians(heading_deg))
    mission(name, [(round(ux * d, 1), round(uy * d, 1)) for d in stations])


if __name__ == "__main__":
    # Six drones through one point at once, 1.8 km out, headings 60 degrees apart.
    six = [f"busy_six_{i}" for i in range(1, 7)]
    for i, name in enumerate(six):
        through_centre(name, 60.0 * i + 15.0, [-1800, -600, 600, 1800])
    scenario(
        "busy_six",
        """Six drones through one point at once, 1.8 km out on headings 60 degrees apart
(US915 SF7, 10 % loss): fifteen pairs, every one a conflict at the centre.""",
        [(name, "") for name in six],
        seed=41,
        time_limit_s=900,
        time_scale=20,
    )
    # Ten drones over one 4 km neighbourhood: five fly east side by side (800 m apart), five
    # north; the north drones start further out, so most ground tracks cross minutes apart --
    # except drone 8, which reaches the centre with drone 3.
    ten: list[tuple[str, str]] = []
    for i in range(5):
        y = -1600 + 800 * i
        mission(f"busy_ten_e{i}", [(-2200, y), (-800, y), (800, y), (2200, y)])
        ten.append((f"busy_ten_e{i}", ""))
    for j in range(5):
        x = -1600 + 800 * j
        start = -2200 if j == 2 else -2200 - 2400 - 400 * j
        mission(f"busy_ten_n{j}", [(x, start), (x, -800), (x, 800), (x, 2200)])
        ten.append((f"busy_ten_n{j}", ""))
    scenario(
        "busy_ten",
        """Ten drones over one 4 km neighbourhood (US915 SF7, 10 % loss): five fly east 800 m
apart, five north; the north drones start 2.4-4 km further out and cross the east drones'
tracks minutes after them, except drone 8, which meets drone 3 at the centre: one real
conflict among 45 pairs.""",
        ten,
        seed=42,
        time_limit_s=1500,
        time_scale=30,
    )
    # Four drones through one point, EU868's 869.4-869.65 MHz sub-band (10 % duty cycle).
    four = [f"busy_four_{i}" for i in range(1, 5)]
    for i, name in enumerate(four):
        through_centre(name, 90.0 * i + 30.0, [-2400, -800, 800, 2400])
    scenario(
        "busy_four_eu868",
        """Four drones through one point at once, 2.4 km out on headings 90 degrees apart, on
EU868's 10 % sub-band (SF7, 10 % loss): six pairs, every one a conflict at the centre.""",
        [(name, "") for name in four],
        seed=43,
        time_limit_s=1000,
        time_scale=20,
    )
    # the link profile of the EU868 scenario
    path = OUT / "busy_four_eu868.toml"
    path.write_text(path.read_text().replace('"us915-sf7"', '"eu868-g3-sf7"'))
