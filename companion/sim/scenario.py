"""Replay scenarios: a TOML file read and checked whole (:mod:`companion.app.tables`).

A scenario::

    time_scale = 20          # simulated seconds per real second
    time_limit_s = 900       # simulated
    offset_m = 10            # optional
    lookahead_s = 60         # optional: the near run covers at least this much flight
    failsafe = "climb"       # optional: "climb", "hold" or "off"
    [link]
    profile = "us915-sf7"
    loss = 0.1
    seed = 1
    channels = 1             # optional: of the region's channels (us915: 8, eu868: 3)
    [[drone]]
    id = 1
    mission = "a.plan"       # relative to the scenario file
    takeoff_delay_s = 0      # optional
    autopilot = "px4"        # or "ardupilot"
    hold_for_comparisons = true  # optional: take-off waits for a comparison under way
    pause_at_s = 120         # optional: held in flight at this time (an operator's hold,
    pause_for_s = 240        # a head wind): a delay the companion did not foresee
    operator = "fleet"       # optional: whose certificate it flies with
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from companion.app.tables import Table, TableError, load_toml
from companion.auth.trust import UnknownPeers
from companion.mission.files import read_mission_file
from companion.mission.flightpath import FlightPath, flight_path
from companion.mission.items import MissionError, MissionItem
from companion.radio.airtime import PROFILES
from companion.runs.failsafe import Action
from companion.sim.mock_links import Faults

MAX_TIME_SCALE = 10_000.0  # simulated seconds per real second: lossy_sf9 flies at 2000
MAX_LOSS = 0.9  # more loss than this and no run ends: a scenario for nothing


class ScenarioError(TableError):
    """The scenario file is invalid."""


@dataclass(frozen=True)
class DroneSpec:
    id: int
    mission: list[MissionItem]
    home: tuple[float, float, float]
    takeoff_delay_s: float = 0.0
    ardupilot: bool = False
    faults: Faults = field(default_factory=Faults)  # of its mock autopilot
    companion_stop_s: float | None = None  # the companion vanishes at this simulated time
    companion_stop_in_run: bool = False  # ... or later, once it has a run on the air
    hold_for_comparisons: bool = True  # on the ground, take-off waits for a running run
    operator: str = "fleet"  # whose certificate it flies with
    pause: tuple[float, float] | None = None  # held in flight (at, for how long), simulated
    companion_start_s: float = 0.0  # its companion powers up at this simulated time
    companion_off_landed: bool = False  # ... and off once its mission is flown

    @property
    def path(self) -> FlightPath:
        """The ground path the vehicle flies (launch leg from home included)."""
        home = (round(self.home[0] * 1e7), round(self.home[1] * 1e7))
        return flight_path(self.mission, home, ardupilot=self.ardupilot)


@dataclass(frozen=True)
class Scenario:
    name: str
    time_scale: float
    time_limit_s: float
    link_profile: str
    loss: float
    seed: int | None
    drones: list[DroneSpec]
    offset_m: float = 10.0
    separation_m: float = 15.0
    vertical_separation_m: float = 10.0
    cruise_m_s: float = 10.0
    beacon_interval_s: float = 5.0
    grid_radius_m: float = 500.0
    grid_resolution_mm: int = 2000
    lookahead_s: float = 60.0
    failsafe: Action = Action.CLIMB
    untrusted_operators: frozenset[str] = frozenset()  # not in the other drones' trust stores
    unknown_peers: UnknownPeers = UnknownPeers.IGNORE
    radio_range_m: float | None = None  # radios farther apart do not hear each other
    channels: int = 1  # of the region's, used by the links (companion.radio.config)

    def trusted_pair(self, a: DroneSpec, b: DroneSpec) -> bool:
        """Both drones deconflict with each other (neither is of an untrusted operator)."""
        return not {a.operator, b.operator} & self.untrusted_operators


def load_scenario(path: str | Path) -> Scenario:
    """Read and check a scenario file whole (:mod:`companion.app.tables`): every number finite
    and in range, every mission readable, no unknown key."""
    path = Path(path)
    doc = Table(load_toml(path, ScenarioError), str(path), ScenarioError)
    time_scale = doc.number("time_scale", 20.0, low=0.0, above=True)
    if time_scale > MAX_TIME_SCALE:
        raise doc.fail(f"{time_scale:g} is out of range (at most {MAX_TIME_SCALE:g})", "time_scale")
    time_limit_s = doc.number("time_limit_s", 900.0, low=0.0, above=True)
    link = doc.table("link")
    link_profile = link.text("profile", "us915-sf7", list(PROFILES))
    loss = link.number("loss", 0.0, low=0.0, high=MAX_LOSS)
    seed = link.optional_integer("seed", low=0)
    channels = link.integer("channels", 1, low=1)
    if channels > PROFILES[link_profile].channels:
        raise link.fail(
            f"{channels} is out of range ({link_profile} has {PROFILES[link_profile].channels})",
            "channels",
        )
    drones = _drones(doc, path)
    failsafe = doc.text("failsafe", "climb", [a.value for a in Action])
    untrusted = doc.strings("untrusted_operators")
    if not {d.operator for d in drones} - set(untrusted):
        raise doc.fail("every operator is untrusted", "untrusted_operators")
    policy = doc.text("unknown_peers", "ignore", [p.value for p in UnknownPeers])
    scenario = Scenario(
        name=path.stem,
        time_scale=time_scale,
        time_limit_s=time_limit_s,
        link_profile=link_profile,
        loss=loss,
        seed=seed,
        drones=drones,
        offset_m=doc.number("offset_m", 10.0, low=0.0, above=True),
        separation_m=doc.number("separation_m", 15.0, low=0.0),
        vertical_separation_m=doc.number("vertical_separation_m", 10.0, low=0.0),
        cruise_m_s=doc.number("cruise_m_s", 10.0, low=0.0, above=True),
        beacon_interval_s=doc.number("beacon_interval_s", 5.0, low=0.0, above=True),
        grid_radius_m=doc.number("grid_radius_m", 500.0, low=0.0, above=True),
        grid_resolution_mm=doc.integer("grid_resolution_mm", 2000, low=1),
        lookahead_s=doc.number("lookahead_s", 60.0, low=0.0),
        failsafe=Action(failsafe),
        untrusted_operators=frozenset(untrusted),
        unknown_peers=UnknownPeers(policy),
        channels=channels,
    )
    doc.finish()
    return scenario


def _drones(doc: Table, path: Path) -> list[DroneSpec]:
    """The ``[[drone]]`` tables: at least two, each with an id of its own."""
    raw_drones = doc.tables("drone", "drone")
    if len(raw_drones) < 2:
        raise doc.fail("at least two [[drone]] tables are needed")
    drones, ids = [], set()
    for raw in raw_drones:
        ident = raw.integer("id", low=1, high=0xFFFE)
        if ident in ids:
            raise raw.fail(f"{ident} is taken by another drone", "id")
        ids.add(ident)
        drones.append(_drone(raw, ident, path))
    return drones


def _drone(raw: Table, ident: int, path: Path) -> DroneSpec:
    """One ``[[drone]]`` table (its id read already), its mission read and checked."""
    kind = raw.text("autopilot", "px4", ("px4", "ardupilot"))
    items, home = _mission(raw, path, ardupilot=kind == "ardupilot")
    return DroneSpec(
        ident,
        items,
        home,
        raw.number("takeoff_delay_s", 0.0, low=0.0),
        kind == "ardupilot",
        hold_for_comparisons=raw.flag("hold_for_comparisons", True),
        operator=raw.text("operator", "fleet"),
        pause=_pause(raw),
    )


def _mission(
    raw: Table, path: Path, *, ardupilot: bool
) -> tuple[list[MissionItem], tuple[float, float, float]]:
    """A drone's mission file (relative to the scenario ``path``): its items for the
    autopilot, their flown path valid, and its home."""
    mission_file = raw.text("mission")
    mission_path = path.parent / mission_file
    if not mission_path.is_file():
        what = "is a directory" if mission_path.is_dir() else "does not exist"
        raise raw.fail(
            f"{mission_file} {what} (paths are relative to the scenario's folder)",
            "mission",
        )
    try:
        plan = read_mission_file(mission_path)  # errors name the file
    except MissionError as exc:
        raise raw.fail(str(exc)) from None
    try:
        if plan.home is None:
            raise MissionError("the mission file gives no home")
        items = plan.for_autopilot(ardupilot=ardupilot)
        flight_path(items, plan.home_degE7, ardupilot=ardupilot)  # jumps valid
    except MissionError as exc:
        raise raw.fail(f"{mission_file}: {exc}") from None
    return items, plan.home


def _pause(raw: Table) -> tuple[float, float] | None:
    """``pause_at_s`` and ``pause_for_s``: both or neither."""
    given = [key for key in ("pause_at_s", "pause_for_s") if key in raw.doc]
    if not given:
        return None
    if len(given) == 1:
        raise raw.fail("pause_at_s and pause_for_s go together", given[0])
    return raw.number("pause_at_s", low=0.0), raw.number("pause_for_s", low=0.0, above=True)
