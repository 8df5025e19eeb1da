"""Write the separation scenarios (``sitl_configs/scenarios/sep_*.plan`` and ``sep_*.toml``).

Each is a case where separation in space and time, not crossing lines, decides (issue 26):
near misses whose tracks never cross, altitude that makes a crossing no conflict (or a worse
one), time that does, a crossing in the middle of a first leg, a drone held up on its way,
and six drones whose tracks cross at different times.  Every drone flies at 30 m above a home
at 488 m unless said otherwise; distances are metres east/north of a common point C, on the
project's one Earth model (:func:`protocol.geo.geodesy.moved`).  Run from the repository root:
``.venv/bin/python scripts/make_separation_scenarios.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from companion.mission.files import format_plan
from companion.mission.items import (
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    MissionItem,
)
from protocol.geo.geodesy import moved
from protocol.tools.cli import write_atomic

C = (47.4010, 8.5500)
HOME_AMSL = 488.0
OUT = Path(__file__).resolve().parent.parent / "sitl_configs" / "scenarios"

Point = tuple[float, float]  # metres east, north of C


def at(p: Point) -> tuple[float, float]:
    return moved(C[0], C[1], p[1], p[0])


def mission(
    name: str, legs: Sequence[Point], alt: float = 30.0, loiter: dict[int, float] | None = None
) -> None:
    """Take-off over the first point to ``alt``, waypoints through ``legs`` (a loiter of the
    given seconds at the leg indices in ``loiter``), a landing 20 m past the last."""
    loiter = loiter or {}

    def item(command: int, p: Point, z: float, hold: float = 0.0) -> MissionItem:
        lat, lon = at(p)
        return MissionItem(
            len(items), 3, command, 0, 1, hold, 0.0, 0.0, math.nan,
            round(lat * 1e7), round(lon * 1e7), z,
        )  # fmt: skip

    items = [MissionItem(0, 3, NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0, math.nan, 0, 0, alt)]
    for i, p in enumerate(legs):
        if i in loiter:
            items.append(item(NAV_LOITER_TIME, p, alt, loiter[i]))
        else:
            items.append(item(NAV_WAYPOINT, p, alt))
    (x0, y0), (x1, y1) = legs[-2], legs[-1]
    d = math.hypot(x1 - x0, y1 - y0)
    items.append(item(NAV_LAND, (x1 + 20 * (x1 - x0) / d, y1 + 20 * (y1 - y0) / d), 0.0))
    home = at(legs[0])
    write_atomic(OUT / f"{name}.plan", format_plan(items, [home[0], home[1], HOME_AMSL]))


def scenario(name: str, comment: str, drones: list[tuple[str, str]], **keys: object) -> None:
    """A two-or-more-drone scenario, all airborne from the start (US915 SF7, 10 % loss)."""
    lines = [f"# {line}".rstrip() for line in comment.strip().splitlines()]
    head = {"time_scale": 10, "time_limit_s": 400, **keys}
    lines += [f"{k} = {v}" for k, v in head.items() if k != "seed"]
    lines += ["[link]", 'profile = "us915-sf7"', "loss = 0.1", f"seed = {keys.get('seed', 1)}"]
    for i, (plan, extra) in enumerate(drones, start=1):
        lines += [
            "[[drone]]",
            f"id = {i}",
            f'mission = "{plan}.plan"',
        ]
        if "hold_for_comparisons" not in extra:  # airborne at once: nothing to wait for
            lines.append("hold_for_comparisons = false")
        lines += [line for line in extra.splitlines() if line]
    (OUT / f"{name}.toml").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    # Head-on on parallel tracks 3 m apart, meeting about 120 s after take-off.
    mission("sep_parallel_east", [(-1200, 0), (-400, 0), (400, 0), (1200, 0)])
    mission("sep_parallel_west", [(1200, 3), (400, 3), (-400, 3), (-1200, 3)])
    scenario(
        "sep_parallel",
        """Head-on on parallel tracks 3 m apart at one altitude: the tracks never cross, the
drones pass 3 m apart.  Within the 15 m separation: a conflict; one drone climbs over the
legs the other flies beside.""",
        [("sep_parallel_east", ""), ("sep_parallel_west", "")],
        seed=31,
        time_scale=25,
    )
    # A leg that turns away 2 m short of the other track and runs beside it.
    mission("sep_tee_north", [(0, -1300), (0, -300), (0, 500), (0, 1300)])
    mission("sep_tee_east", [(-1280, 0), (-400, 0), (-2, 0), (-2, 300), (-600, 600)])
    scenario(
        "sep_tee",
        """A tee that stops short: drone 2 flies east and turns north 2 m before drone 1's
track, as drone 1 comes by, and runs beside it.  The tracks never cross.""",
        [("sep_tee_north", ""), ("sep_tee_east", "")],
        seed=32,
        time_scale=25,
    )
    # A track that passes 4 m beyond the end of the other: drone 2 hovers at its last point.
    mission("sep_graze_hover", [(-900, 0), (-300, 0), (0, 0), (0, -200)], loiter={2: 200.0})
    mission("sep_graze_north", [(4, -1300), (4, -500), (4, 500), (4, 1300)])
    scenario(
        "sep_graze",
        """A graze: drone 2 flies east and hovers for 200 s at the end of its track; drone 1
passes north 4 m beyond that end.  The tracks never cross.""",
        [("sep_graze_north", ""), ("sep_graze_hover", "")],
        seed=33,
        time_scale=25,
    )
    # Crossing at right angles; drone 2 cruises 5 m higher.
    mission("sep_cross_east", [(-1200, 0), (-400, 0), (400, 0), (1200, 0)])
    mission("sep_cross_north_35", [(0, -1200), (0, -400), (0, 400), (0, 1200)], alt=35.0)
    scenario(
        "sep_higher5",
        """A crossing under a drone that cruises 5 m higher: within the vertical separation,
a conflict; whoever climbs must end at least 10 m clear of the other's altitude (a climb of
one offset from below would bring it within 5 m: worse than flying level).""",
        [("sep_cross_east", ""), ("sep_cross_north_35", "")],
        seed=34,
        time_scale=25,
    )
    # (it climbs 60 m more at take-off: 20 s, 190 m closer to be over C when drone 1 is)
    mission("sep_cross_north_90", [(0, -1010), (0, -400), (0, 400), (0, 1200)], alt=90.0)
    scenario(
        "sep_higher60",
        """The same crossing with drone 2 60 m higher: no conflict, no edit, no precaution.""",
        [("sep_cross_east", ""), ("sep_cross_north_90", "")],
        seed=35,
        time_scale=30,
    )
    # The same crossing, drone 2 there about four minutes after drone 1.
    mission(
        "sep_later_north", [(0, -1200), (0, -900), (0, -400), (0, 400), (0, 1200)],
        loiter={1: 240.0},
    )  # fmt: skip
    scenario(
        "sep_later",
        """Drone 2 crosses drone 1's track about four minutes after drone 1 passed (it
inspects a point on its way for 240 s first): separated in time, no conflict, no edit.""",
        [("sep_cross_east", ""), ("sep_later_north", "")],
        seed=36,
        time_limit_s=600,
        time_scale=30,
    )
    scenario(
        "sep_delayed",
        """Drone 1 is held up for 248 s on its way (an operator's hold, a head wind): it now
reaches the crossing when drone 2 does.  It has left its time windows: both compare again,
find the conflict and deconflict it.""",
        [("sep_cross_east", "pause_at_s = 20\npause_for_s = 248"), ("sep_later_north", "")],
        seed=37,
        time_limit_s=700,
        time_scale=30,
    )
    # A crossing in the middle of a first leg, found in flight.
    mission("sep_first_leg_east", [(-800, 0), (800, 0)])
    mission("sep_first_leg_mast", [(0, -700), (0, 0), (0, -300)], loiter={1: 200.0})
    scenario(
        "sep_first_leg",
        """Drone 2 hovers over a mast in the middle of drone 1's first leg (take-off, then 1.6
km east).  Drone 1 learns it in flight, on that leg: its climb must be over before the
mast, not half way up a ramp to a raised waypoint.""",
        [("sep_first_leg_east", ""), ("sep_first_leg_mast", "")],
        seed=38,
        time_limit_s=450,
        time_scale=25,
    )
    # Six drones in two groups (their tracks parallel, 1.5 to 2 km apart): three fly east
    # across a 4 km square from the start, and compare in flight; three wait on the ground
    # 5.5 km south of it, out of radio range of the first three, until they have compared
    # with each other (at least two minutes), and fly north across the square after the
    # first three have passed.  Nine pairs' ground tracks cross, minutes apart; no two drones
    # come within 500 m.  On one channel the second group's comparisons queue behind the
    # first group's, so its take-offs spread over ten minutes (a busy sky, issue 29).
    waves = [
        ("sep_six_1", [(-2000, 2000), (-700, 2000), (700, 2000), (2000, 2000)]),
        ("sep_six_2", [(-2000, 0), (-700, 0), (700, 0), (2000, 0)]),
        ("sep_six_3", [(-2000, -2000), (-700, -2000), (700, -2000), (2000, -2000)]),
        ("sep_six_4", [(-1500, -7500), (-1500, -2600), (-1500, 0), (-1500, 2600)]),
        ("sep_six_5", [(0, -7500), (0, -2600), (0, 0), (0, 2600)]),
        ("sep_six_6", [(1500, -7500), (1500, -2600), (1500, 0), (1500, 2600)]),
    ]  # fmt: skip
    for name, legs in waves:
        mission(name, legs)
    scenario(
        "sep_six",
        """Six drones whose tracks cross at different times: three cross a 4 km square east
side by side, three more wait 5.5 km south of it until they have compared with each other and
then cross it north, after the first three have passed.  Nine pairs' tracks cross, minutes
apart; no two drones come within 500 m.  No conflict: no edit and no precaution.""",
        [
            (name, "takeoff_delay_s = 120\nhold_for_comparisons = true" if i >= 3 else "")
            for i, (name, _) in enumerate(waves)
        ],
        seed=39,
        time_limit_s=3000,
        time_scale=50,
    )
