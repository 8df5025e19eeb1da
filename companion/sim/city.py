"""A fleet-scale simulation: a city's hour of drone traffic in virtual time (issue 29).

``drone-deconflict fleet --drones 100 --hours 1``.  :func:`city_scenario` makes the traffic --
``drones`` delivery flights (out to a point 0.8-2.5 km away and back, at one of a few cruise
altitudes) from homes spread over a square of ``area_km``, their take-offs spread over the
hours, each drone's companion powered up a minute before its take-off and off once it has
landed, radios that hear each other within ``range_km`` -- and :func:`run_city` flies it as a
virtual replay (:func:`companion.sim.replay.run_virtual`: the companions' own components, the
in-process vehicles, the simulated channel; no MAVSDK) and sums it up per drone-hour
(:class:`CityReport`): runs, bytes, airtime and the channel load around each drone, conflicts,
precautions and resolutions, and a table of drones in range against those outcomes.  The
replay over MAVSDK stays the reference for small scenarios.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import asdict, dataclass

from companion.mission.items import NAV_LAND, NAV_TAKEOFF, NAV_WAYPOINT, MissionItem
from companion.sim.replay import Replay, run_virtual
from companion.sim.report import ReplayReport
from companion.sim.scenario import DroneSpec, Scenario
from companion.sim.vehicles import Track
from protocol.geo.geodesy import ground_offset, moved

CENTRE = (47.3900, 8.5300)  # the city's centre (lat, lon)
HOME_AMSL = 450.0
ALTITUDES_M = (30.0, 40.0, 50.0, 60.0)  # cruise altitudes above home, drawn per flight
WARM_UP_S = 60.0  # a companion powers up this long before its take-off
SAMPLE_S = 10.0  # drones in range are counted this often
BANDS = ((0, 2), (2, 5), (5, 10), (10, 1_000))  # drones in range, [low, high)


@dataclass(frozen=True)
class CitySpec:
    """The traffic of a fleet simulation (see the module)."""

    drones: int = 100
    hours: float = 1.0
    area_km: float = 6.0
    range_km: float = 3.0
    seed: int = 1
    profile: str = "us915-sf7"
    loss: float = 0.1
    legs_km: tuple[float, float] = (0.8, 2.5)

    def __post_init__(self) -> None:
        if not 2 <= self.drones <= 250:
            raise ValueError(f"{self.drones} drones: 2..250")
        if not 0 < self.hours <= 8:
            raise ValueError(f"{self.hours} hours: above 0, at most 8")
        if self.area_km <= 0 or self.range_km <= 0:
            raise ValueError("area and range must be above 0")
        if not 0.0 <= self.loss < 0.9:
            raise ValueError(f"loss {self.loss} outside [0, 0.9)")


def _flight(
    rng: random.Random, spec: CitySpec
) -> tuple[tuple[float, float, float], list[MissionItem]]:
    """One delivery: a home in the square, out to a point and back, landing beside home."""
    half = spec.area_km * 500.0
    hx, hy = rng.uniform(-half, half), rng.uniform(-half, half)
    bearing = rng.uniform(0.0, 2 * math.pi)
    length = rng.uniform(*spec.legs_km) * 1000.0
    dx = min(max(hx + length * math.sin(bearing), -half), half)
    dy = min(max(hy + length * math.cos(bearing), -half), half)
    alt = rng.choice(ALTITUDES_M)

    def at(east: float, north: float) -> tuple[int, int]:
        lat, lon = moved(CENTRE[0], CENTRE[1], north, east)
        return round(lat * 1e7), round(lon * 1e7)

    def item(command: int, point: tuple[int, int], z: float) -> MissionItem:
        return MissionItem(len(items), 3, command, 0, 1, 0.0, 0.0, 0.0, math.nan, *point, z)

    items = [MissionItem(0, 3, NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0, math.nan, 0, 0, alt)]
    items.append(item(NAV_WAYPOINT, at(dx, dy), alt))
    items.append(item(NAV_WAYPOINT, at(hx, hy), alt))
    items.append(item(NAV_LAND, at(hx + 20.0, hy), 0.0))
    lat, lon = moved(CENTRE[0], CENTRE[1], hy, hx)
    return (lat, lon, HOME_AMSL), items


def city_scenario(spec: CitySpec) -> Scenario:
    """The fleet simulation's traffic as a scenario (seeded: the same spec, the same sky)."""
    rng = random.Random(spec.seed)  # noqa: S311  (a simulation's traffic, never a key)
    window = spec.hours * 3600.0
    drones = []
    for ident in range(1, spec.drones + 1):
        home, mission = _flight(rng, spec)
        takeoff = rng.uniform(WARM_UP_S, max(window - 600.0, WARM_UP_S + 1.0))
        drones.append(
            DroneSpec(
                ident,
                mission,
                home,
                takeoff_delay_s=round(takeoff, 1),
                hold_for_comparisons=False,  # a schedule: it leaves on time
                companion_start_s=round(takeoff - WARM_UP_S, 1),
                companion_off_landed=True,
            )
        )
    return Scenario(
        name=f"city-{spec.drones}x{spec.hours:g}h-seed{spec.seed}",
        time_scale=1.0,
        time_limit_s=window + 900.0,
        link_profile=spec.profile,
        loss=spec.loss,
        seed=spec.seed,
        drones=drones,
        radio_range_m=spec.range_km * 1000.0,
    )


@dataclass(frozen=True)
class Band:
    """Drones whose mean number of airborne drones in radio range falls in [low, high)."""

    low: int
    high: int
    drones: int
    drone_hours: float
    runs: float  # per drone-hour
    kbytes: float  # sent, per drone-hour
    load: float  # airtime on the channel within range, seconds per second (>1: overload)
    precautions: float  # per drone-hour
    conflicts: int  # pairs with a drone in the band inside each other's protected volume
    resolved: int  # without the companions; of those, resolved; false alarms, the same way
    false_alarms: int

    @property
    def span(self) -> str:
        return f"{self.low}-{self.high}" if self.high < BANDS[-1][1] else f"{self.low}+"


@dataclass(frozen=True)
class CityReport:
    spec: CitySpec
    replay: ReplayReport
    drone_hours: float  # airborne
    in_range: dict[int, float]  # drone -> mean airborne drones within radio range
    load: dict[int, float]  # drone -> channel load around it while airborne
    bands: list[Band]

    @property
    def runs(self) -> int:
        """Runs that gave a result, all drones together."""
        return sum(len(d.runs) for d in self.replay.drones)

    @property
    def bytes_sent(self) -> int:
        return sum(d.bytes_sent for d in self.replay.drones)

    @property
    def precautions(self) -> int:
        return sum(len(d.precautionary) for d in self.replay.drones)


def _airborne(track: Track, home_amsl: float) -> list[tuple[float, float, float, float]]:
    return [s for s in track if s[3] > home_amsl + 1.0]


Grid = dict[int, dict[int, tuple[float, float]]]  # second -> drone -> (north, east) metres


def _neighbours(
    flown: dict[int, list[tuple[float, float, float, float]]], range_m: float
) -> tuple[dict[int, float], Grid]:
    """Mean number of other airborne drones in range of each airborne drone (sampled every
    SAMPLE_S), and where each drone is in every whole second it is airborne (for the load)."""
    grid: Grid = {}
    for ident, track in flown.items():
        for t, lat, lon, _ in track:
            here = grid.setdefault(int(t), {})
            if ident not in here:
                here[ident] = ground_offset(CENTRE[0], CENTRE[1], lat, lon)
    counts: dict[int, list[int]] = {k: [] for k in flown}
    for second in sorted(grid)[:: int(SAMPLE_S)]:
        here = grid[second]
        for a, pa in here.items():
            counts[a].append(
                sum(1 for b, pb in here.items() if b != a and math.dist(pa, pb) <= range_m)
            )
    return {k: sum(v) / len(v) if v else 0.0 for k, v in counts.items()}, grid


def _loads(
    log: Sequence[tuple[float, float, int]],
    grid: Grid,
    airborne_s: dict[int, float],
    range_m: float,
) -> dict[int, float]:
    """Seconds on air per second airborne of every frame sent within range of each drone
    while it is airborne (its own included)."""
    busy = {k: 0.0 for k in airborne_s}
    for start, end, src in log:
        here = grid.get(int(start))
        if not here or src not in here:
            continue  # sent on the ground: before take-off or after landing
        ps = here[src]
        for k, pk in here.items():
            if k == src or math.dist(ps, pk) <= range_m:
                busy[k] += end - start
    return {k: busy[k] / airborne_s[k] if airborne_s[k] else 0.0 for k in busy}


def summarise(
    spec: CitySpec, replay: Replay, log: Sequence[tuple[float, float, int]]
) -> CityReport:
    """Per drone-hour figures and the drones-in-range table of a flown city."""
    report = replay.report
    ids = {d.id for d in report.drones}
    flown = {k: _airborne(track, HOME_AMSL) for k, track in replay.tracks.flown.items() if k in ids}
    airborne_s = {k: (v[-1][0] - v[0][0]) if len(v) > 1 else 0.0 for k, v in flown.items()}
    range_m = spec.range_km * 1000.0
    in_range, grid = _neighbours(flown, range_m)
    load = _loads(log, grid, airborne_s, range_m)
    bands = []
    for low, high in BANDS:
        ids = {k for k, n in in_range.items() if low <= n < high}
        hours = sum(airborne_s[k] for k in ids) / 3600.0
        scale = 1.0 / hours if hours > 0 else 0.0
        drones = [d for d in report.drones if d.id in ids]
        pairs = [p for p in report.pairs if p.drones[0] in ids or p.drones[1] in ids]
        bands.append(
            Band(
                low,
                high,
                len(ids),
                round(hours, 2),
                round(scale * sum(len(d.runs) for d in drones), 1),
                round(scale * sum(d.bytes_sent for d in drones) / 1000.0, 1),
                round(sum(load[k] * airborne_s[k] for k in ids) / (hours * 3600.0), 3)
                if hours > 0
                else 0.0,
                round(scale * sum(len(d.precautionary) for d in drones), 2),
                sum(p.conflict for p in pairs),
                sum(p.resolved for p in pairs),
                sum(p.false_alarm for p in pairs),
            )
        )
    return CityReport(
        spec,
        report,
        round(sum(airborne_s.values()) / 3600.0, 2),
        in_range,
        load,
        bands,
    )


def run_city(spec: CitySpec, *, progress: bool = False) -> CityReport:
    """Fly the city of ``spec`` in virtual time and sum it up."""
    scenario = city_scenario(spec)
    log: list[tuple[float, float, int]] = []
    replay = run_virtual(scenario, progress=progress, channel_log=log)
    return summarise(spec, replay, log)


def format_city(city: CityReport) -> str:
    """The fleet simulation's summary and its drones-in-range table."""
    spec, r = city.spec, city.replay
    hours = city.drone_hours or math.inf
    lines = [
        f"Fleet simulation {r.scenario}: {spec.drones} drones over {spec.area_km:g} km x "
        f"{spec.area_km:g} km for {spec.hours:g} h, radio range {spec.range_km:g} km, "
        f"{spec.profile} at {spec.loss:.0%} loss, in virtual time",
        f"  {city.drone_hours:.1f} drone-hours airborne; all missions flown: "
        f"{'yes' if r.finished else 'NO'}",
        f"  per drone-hour: {city.runs / hours:.1f} runs, {city.bytes_sent / 1000 / hours:.1f} "
        f"KB sent, {city.precautions / hours:.2f} precautions",
        f"  conflicts {r.conflicts}, resolved {r.conflicts_resolved}, false alarms "
        f"{r.false_alarms}, made worse {r.made_worse}, precautions {city.precautions}",
        "",
        "  in range  drones  drone-h  runs/h  KB/h  load  precautions/h  conflicts  resolved  "
        "false alarms",
    ]
    for b in city.bands:
        lines.append(
            f"  {b.span:>8}  {b.drones:>6}  {b.drone_hours:>7.2f}  {b.runs:>6.1f}  {b.kbytes:>4.0f}"
            f"  {b.load:>4.2f}  {b.precautions:>13.2f}  {b.conflicts:>9}  {b.resolved:>8}  "
            f"{b.false_alarms:>12}"
        )
    return "\n".join(lines)


def city_json(city: CityReport) -> dict[str, object]:
    """The summary as JSON (``fleet --json``); the whole replay report is ``--out``'s."""
    r = city.replay
    return {
        "spec": asdict(city.spec),
        "finished": r.finished,
        "drone_hours": city.drone_hours,
        "runs": city.runs,
        "bytes_sent": city.bytes_sent,
        "precautions": city.precautions,
        "conflicts": r.conflicts,
        "conflicts_resolved": r.conflicts_resolved,
        "false_alarms": r.false_alarms,
        "made_worse": r.made_worse,
        "bands": [asdict(b) for b in city.bands],
        "drones": {
            str(k): {"in_range": round(city.in_range[k], 2), "load": round(city.load[k], 3)}
            for k in sorted(city.in_range)
        },
    }
