"""Our own flight: the mission as read, as held and as edited, and when and where it is flown.

:class:`OwnFlight` owns the mission (the original, the one the vehicle holds, the verified
edit and its raises), its flown path, and its schedule -- each segment's band and time window
as the flight model flies it from the vehicle's state (:func:`companion.mission.schedule.predict`)
-- and keeps to it: off its windows by half the tolerance, or holding, the schedule's epoch
moves on and every peer compares again (:meth:`OwnFlight.keep_time`).  What our beacons
announce of it (version, altitude slots, size class) comes from here too.
"""

from __future__ import annotations

import asyncio
import hashlib
import math
from collections.abc import Callable, Sequence

from companion.context import Context
from companion.events import EventKind, Retimed
from companion.mission.flight_model import MAX_PREDICTION_S, Kinematics
from companion.mission.flightpath import FlightPath, flight_path
from companion.mission.ground import cut_behind, distance_m, near_answer, near_cut
from companion.mission.items import NAV_LOITER_TIME, NAV_WAYPOINT, MissionItem
from companion.mission.levels import Slots, reach, reaching
from companion.mission.planner import Edit
from companion.mission.planner import Vehicle as PlanVehicle
from companion.mission.schedule import Schedule, Vehicle, off_schedule, predict
from companion.mission.vehicle import VehicleState
from protocol.geo.grid import GridSpec
from protocol.messages import Suite
from protocol.run import DEFAULT_LIMITS

OVER_ITEM_M = 5.0  # this close to its current item's point, the vehicle is holding there
TIMING_LOOK_S = 180.0  # how far ahead the timing watch predicts (the full schedule is kept)
TIMING_EVERY_S = 5.0  # and how often
PREDICTIONS_KEPT = 8  # schedules remembered for a vehicle state (several paths and limits)
CUT_BACK_M = 5.0  # a run's first leg starts this far behind the drone (position error, lag)
NEAR_SEGMENTS = 2  # a near run compares at least our next two segments as Alice


def mission_version(path: FlightPath, items: Sequence[MissionItem] = (), epoch: int = 0) -> int:
    """16-bit digest of the path in four dimensions: the ground track, the items' altitudes
    and the schedule's epoch (bumped when the drone falls behind or ahead of its windows)."""
    flown = (path.points, [round(it.z, 2) for it in items], epoch)
    digest = hashlib.sha256(repr(flown).encode()).digest()
    return int.from_bytes(digest[:2], "big")


def same_track(a: list[MissionItem], b: list[MissionItem]) -> bool:
    """The same items in the same places (altitudes and the current mark aside)."""
    return len(a) == len(b) and all(
        (x.command, x.x, x.y, x.mission_type) == (y.command, y.x, y.y, y.mission_type)
        for x, y in zip(a, b, strict=True)
    )


def box_radius_m(
    path: list[tuple[int, int]], centre: tuple[int, int], minimum: float, room_m: float = 0.0
) -> float:
    """The comparison box's radius: ``minimum``, doubled until it holds the path with room
    to spare (the box's edge then stays clear of Alice's path by more than ``room_m``, the
    separation: Bob's path is cut to the box)."""
    extent = max((distance_m(centre, p) for p in path), default=0.0) * 1.1 + 50.0 + room_m
    radius = minimum
    while radius < extent:
        radius *= 2
    return radius


class OwnFlight:
    """The mission we fly and its schedule (see the module).  ``on_retimed``: our windows
    moved (our beacons should say so at once)."""

    def __init__(self, ctx: Context, vehicle: VehicleState, on_retimed: Callable[[], None]) -> None:
        self.ctx = ctx
        self.settings = ctx.settings
        self.vehicle = vehicle
        self._on_retimed = on_retimed
        self.original: list[MissionItem] = []
        self.mission: list[MissionItem] = []
        self.home: tuple[int, int, float] | None = None  # lat, lon degE7, alt AMSL
        self.path = FlightPath(())  # the flown ground path of the original mission
        self.raises: dict[int, float] = {}  # segment -> metres higher, as uploaded
        self.edit: Edit | None = None  # the last verified upload (None: the original flies)
        self.retimed = 0  # the schedule's epoch: bumped when the drone leaves its windows
        self.editing = asyncio.Lock()  # held while the mission on the vehicle changes
        self._timing: tuple[int, float, Schedule] | None = None  # (held mission, when, what)
        self._over_item: tuple[int, float] | None = None  # (current item, over it since)
        self._progress_seen: tuple[int, int, float] = (0, 0, 0.0)  # (current, of, when)
        self._planned: Schedule | None = None  # the original mission from the ground
        self._predictions: dict[
            tuple[object, ...], tuple[list[MissionItem], FlightPath, Schedule]
        ] = {}  # the last few schedules, by what they were predicted from
        self._slots_of: tuple[tuple[object, ...], Slots] | None = None  # (for what, slots)
        self._ground_since: float | None = None  # on the ground: since when its windows hold
        self._ground_retimes = 0  # ... and how often they were moved on there (each doubles)

    def load(
        self,
        items: list[MissionItem],
        home: tuple[int, int, float] | None,
        path: FlightPath | None = None,
    ) -> None:
        """The mission read from the vehicle at the start, its home, and its flown path
        (built here unless given; a mission whose path cannot be built raises
        :class:`~companion.mission.items.MissionError` and is flown uncompared)."""
        self.original, self.mission, self.home = items, list(items), home
        if path is None:
            ground = None if home is None else home[:2]
            path = flight_path(items, ground, ardupilot=self.settings.ardupilot)
        self.path = path

    def progress(self, current: int, total: int, now: float) -> None:
        """The autopilot's mission progress: the current item, unless an edit is being
        uploaded (the vehicle numbers the items of the new mission, and we hold the old one
        until the read-back is done)."""
        self._progress_seen = (current, total, now)
        if total == len(self.mission) or not self.editing.locked():
            self.vehicle.current_item = current

    def edited(
        self, items: list[MissionItem], raises: dict[int, float], edit: Edit, mark: int, sent: float
    ) -> None:
        """A verified upload: the vehicle holds ``items`` flying ``raises``; it flies on from
        what it reported since the upload (sent at link second ``sent``), or from the item the
        upload marked (PX4 goes on from there; its report may not have come yet)."""
        self.mission, self.raises, self.edit = items, raises, edit
        seen, total, when = self._progress_seen
        self.vehicle.current_item = seen if when >= sent and total == len(items) else mark

    @property
    def version(self) -> int:
        """What our beacons announce: the mission the vehicle holds, in four dimensions."""
        return mission_version(self.flown, self.mission, self.retimed)

    @property
    def compare_version(self) -> int:
        """The version of what we compare as Alice (the original mission, on our schedule)."""
        return mission_version(self.path, self.original, self.retimed)

    def reaches(self) -> dict[int, tuple[float, float]]:
        """Segment -> the altitudes (AMSL) a run of ours compares it at besides its schedule's:
        its planned band and that band as far as our raises take it where we fly them
        (:func:`companion.mission.levels.reach`: ramps included)."""
        bands = self.planned_bands()
        out = {}
        for k, extra in reach(self.raises).items():
            if k in bands:
                low, high = bands[k]
                out[k] = (min(low, low + extra), max(high, high + extra))
        return out

    def raises_near(self, slots: Slots) -> frozenset[tuple[int, float]]:
        """Our reaches that come near a drone announcing ``slots`` where the plan did not
        (:func:`companion.mission.levels.reaching`): a run with it compares again when they
        change, a raise that comes near no peer needs no run."""
        vertical = self.settings.separation.vertical_m
        return reaching(self.planned_bands(), reach(self.raises), slots, vertical)

    @property
    def original_current(self) -> int:
        """The vehicle's current item as an item of the original mission."""
        if self.edit is None:
            return self.vehicle.current_item
        origin = self.edit.origin
        return origin[min(max(self.vehicle.current_item, 0), len(origin) - 1)] if origin else 0

    @property
    def flown(self) -> FlightPath:
        """The flown ground path of the mission the vehicle holds (an inserted waypoint
        is a vertex of its own)."""
        if self.edit is None or self.edit.inserted is None:
            return self.path
        home = None if self.home is None else self.home[:2]
        return flight_path(self.mission, home, ardupilot=self.settings.ardupilot)

    @property
    def kinematics(self) -> Kinematics:
        return Kinematics(cruise_m_s=self.settings.cruise_m_s)

    def remaining_path(self) -> tuple[int, list[tuple[int, int]]]:
        """The path still to fly, of the *original* mission (what Alice compares: her edits
        are made on top of it)."""
        return self._remaining(self.path, self.original_current)

    @property
    def done(self) -> bool:
        """Landed after flying, with the mission flown to its last item: nothing left to fly
        or to compare (until another take-off)."""
        v = self.vehicle
        return v.on_ground and v.has_flown and len(self.remaining_path()[1]) < 2

    def remaining_flown(self) -> tuple[int, list[tuple[int, int]]]:
        """The path still to fly, of the mission the vehicle holds (what Bob answers with)."""
        return self._remaining(self.flown, self.vehicle.current_item)

    def _remaining(self, path: FlightPath, current: int) -> tuple[int, list[tuple[int, int]]]:
        """All of ``path`` before the first take-off; in flight from the leg to the current
        item; landed after flying, from there on -- and nothing (the landing point) once the
        current item is the last one on the path, so a drone whose mission is over never
        compares, as Alice, a path it will not fly again."""
        if self.vehicle.on_ground and not self.vehicle.has_flown:
            return 0, path.points
        start = path.start_at(current)
        points = path.points[start:]
        last = max((i for v in path.vertices for i in v.items), default=0)
        if self.vehicle.on_ground and current >= last:
            return len(path.points) - 1, points[-1:]
        return start, points

    def from_here(self, path: list[tuple[int, int]]) -> list[tuple[int, int]]:
        """``path`` (from the leg flown now on: :meth:`remaining_path`, :meth:`remaining_flown`)
        with that leg cut where the drone is, less CUT_BACK_M: what a run compares of it.  A
        leg's flown part is no conflict -- nothing flies it again -- yet it kept a held drone
        waiting until its peer had left the whole leg it crossed on, minutes later."""
        here = self.vehicle.here()
        return list(path) if here is None else cut_behind(path, here, CUT_BACK_M)

    def ahead(self, raises: dict[int, float]) -> dict[int, float]:
        """The raises of the segments not flown yet (all of them before take-off)."""
        first, _ = self.remaining_path()
        return {k: v for k, v in raises.items() if k >= first}

    def own_size(self) -> int:
        """Our remaining path's padded size: our beacons' size class, and as Bob the n of
        every full run (his answer is padded to it) -- of the original mission or of the one
        the vehicle holds, whichever has more segments (an edit may insert a waypoint), so
        that a full run's size shows listeners nothing our beacons do not."""
        segments = max(len(self.remaining_path()[1]), len(self.remaining_flown()[1])) - 1
        return DEFAULT_LIMITS.public_size(segments)

    def home_deg(self) -> tuple[float, float, float]:
        """Home (degrees, metres AMSL): PX4's HOME_POSITION, ArduPilot's item 0, or else
        where the vehicle is, at the altitude its relative altitude counts from."""
        if self.home is not None:
            return self.home[0] / 1e7, self.home[1] / 1e7, self.home[2]
        if self.settings.ardupilot and self.mission:
            first = self.mission[0]
            return first.x / 1e7, first.y / 1e7, first.z
        lat, lon, alt = self.vehicle.position
        return lat / 1e7, lon / 1e7, alt - self.vehicle.relative_alt

    def schedule(
        self,
        items: list[MissionItem],
        path: FlightPath,
        start: int,
        current: int,
        limit_s: float = MAX_PREDICTION_S,
    ) -> Schedule:
        """``path`` (the flown path of ``items``) in four dimensions from vertex ``start``,
        as the flight model flies ``items`` on from where the vehicle is now."""
        home = self.home_deg()
        vehicle = self._vehicle(home, current)
        # The same prediction is asked for again and again between two telemetry samples
        # (a run's plan, its volumes, the fail-safe): flown once per vehicle state.
        key = (id(items), id(path), home, start, vehicle, limit_s)
        hit = self._predictions.get(key)
        if hit is not None and hit[0] is items and hit[1] is path:
            return hit[2]
        schedule = predict(
            path,
            items,
            home,
            start,
            vehicle,
            self.kinematics,
            home_is_item0=self.settings.ardupilot,
            limit_s=limit_s,
        )
        self._predictions[key] = (items, path, schedule)
        while len(self._predictions) > PREDICTIONS_KEPT:
            self._predictions.pop(next(iter(self._predictions)))
        return schedule

    def original_schedule(self, start: int) -> Schedule:
        """The original mission's schedule from segment ``start`` (what Alice compares)."""
        return self.schedule(self.original, self.path, start, self.original_current)

    def held_schedule(self, start: int, limit_s: float = MAX_PREDICTION_S) -> Schedule:
        """The held mission's schedule from segment ``start`` (what Bob answers with)."""
        return self.schedule(
            self.mission, self.flown, start, self.vehicle.current_item, limit_s=limit_s
        )

    def _vehicle(self, home: tuple[float, float, float], current: int) -> Vehicle:
        """The vehicle's state as the flight model starts from it."""
        v = self.vehicle
        lat, lon = v.position[0] / 1e7, v.position[1] / 1e7
        if v.position[:2] == (0, 0):
            lat, lon = home[0], home[1]
        loitering = 0.0
        if self._over_item is not None and self._over_item[0] == v.current_item:
            loitering = v.position_at - self._over_item[1]
        return Vehicle(
            lat,
            lon,
            v.relative_alt,
            v.speed_m_s,
            current,
            v.on_ground,
            loitering,
            v.climb_m_s,
            v.held and not v.on_ground,
            self._ground_wait_left(),
        )

    def planned_bands(self) -> dict[int, tuple[float, float]]:
        """Every segment's band off the ground as planned (the original mission flown from
        the ground), widened by our altitude error: what a raise starts from."""
        if self._planned is None:
            home = self.home_deg()
            self._planned = predict(
                self.path,
                self.original,
                home,
                0,
                Vehicle(*home[:2], 0.0, 0.0, 1 if self.settings.ardupilot else 0, True),
                self.kinematics,
                home_is_item0=self.settings.ardupilot,
            )
        tolerance = self.settings.separation.tolerance
        return {k: self._planned.cruise(k, tolerance) for k in range(self.path.segments)}

    def edit_vehicle(self) -> PlanVehicle:
        """Where the vehicle is, as an edit's planner needs it."""
        lat, lon, amsl = self.vehicle.position
        segment = None if self.vehicle.on_ground else self.path.start_at(self.original_current)
        lead = max(self.vehicle.speed_m_s, 1.0) / self.kinematics.climb_m_s
        return PlanVehicle(segment, lat, lon, self.vehicle.relative_alt, amsl, lead)

    def _ground_allowance(self) -> float:
        """How long a drone on the ground is assumed to wait before it takes off, counted
        from :attr:`_ground_since`: the tolerance's, doubled at each move on the ground."""
        return self.settings.separation.tolerance.ground_wait_s * 2.0**self._ground_retimes

    def _ground_wait_left(self) -> float:
        """On the ground: how much longer it may wait before it takes off and still fly
        within the windows its peers hold (infinite: not on the ground -- or more than half
        the wait is over and :meth:`keep_time` has not moved it on yet: then when it takes
        off is not known)."""
        if not self.vehicle.on_ground or self.vehicle.has_flown:
            return math.inf
        now = self.ctx.clock.now()
        if self._ground_since is None:
            self._ground_since = now
        left = self._ground_since + self._ground_allowance() - now
        return left if left >= self._ground_allowance() / 2 else math.inf

    def wall_of_state(self) -> float:
        """The wall time of the vehicle state predictions start from (its last position)."""
        clock = self.ctx.clock
        if self.vehicle.position_at == 0.0:
            return clock.wall()
        return clock.wall() - (clock.now() - self.vehicle.position_at)

    def note_position(self) -> None:
        """Since when the vehicle has been over its current item's point (a loiter's or a
        waypoint's hold time under way, which the schedule counts down from there)."""
        i = self.vehicle.current_item
        item = (
            self.mission[i] if not self.vehicle.on_ground and 0 <= i < len(self.mission) else None
        )
        if (
            item is None
            or item.command not in (NAV_LOITER_TIME, NAV_WAYPOINT)
            or not item.has_position
            or distance_m(self.vehicle.position[:2], (item.x, item.y)) > OVER_ITEM_M
        ):
            self._over_item = None
        elif self._over_item is None or self._over_item[0] != i:
            self._over_item = (i, self.vehicle.position_at)

    def keep_time(self) -> None:
        """Compare again when the vehicle has left the windows it announced: against the
        schedule predicted at take-off, at the last edit or the last re-timing, a short
        prediction from where it is now shows whether it is off by half the tolerance
        (:func:`companion.mission.schedule.off_schedule`); then the schedule's epoch (part of our
        version) moves on and every peer is due a run again.  On the ground the windows
        assume a take-off within a wait (:meth:`_ground_allowance`): once half of it has passed
        with the drone still there, they move on, the wait doubled.  The paper suite has no
        windows: nothing to keep."""
        if self.editing.locked():  # the mission and its current item are changing
            return
        compact = self.settings.suite is Suite.COMPACT
        if not self.vehicle.on_ground or self.vehicle.has_flown:  # (landed: its mission is over)
            self._ground_since, self._ground_retimes = None, 0
        elif compact:
            now = self.ctx.clock.now()
            if self._ground_since is None:
                self._ground_since = now
            elif now - self._ground_since > self._ground_allowance() / 2:
                self._ground_since = now
                self._ground_retimes += 1
                self._retime(0.0, ground=True)
        if self.vehicle.held and not self.vehicle.on_ground and compact:
            # Holding: when it flies on is unknown, its windows are open to the end from now
            # on (as on the ground).  Once, when the hold begins, its peers compare again.
            if self._timing is not None:
                self._timing = None
                self._retime(0.0)
            return
        if self.vehicle.on_ground or self.vehicle.relative_alt < 1.0 or not compact:
            self._timing = None  # (armed on the ground: the spool-up's length is unknown)
            return
        self._check_drift()

    def _check_drift(self) -> None:
        """In flight: the schedule kept since take-off (or the last edit or re-timing)
        against a short prediction from now; off by half the tolerance, re-timed."""
        start, points = self.remaining_flown()
        if len(points) < 2:
            return
        key = mission_version(self.flown, self.mission)
        now = self.vehicle.position_at  # the predictions start from the vehicle's state then
        if self._timing is None or self._timing[0] != key:
            self._timing = (key, now, self.held_schedule(start))
            return
        _, then, before = self._timing
        soon = self.held_schedule(start, limit_s=TIMING_LOOK_S)
        drift = off_schedule(before, then, soon, now, self.settings.separation.tolerance)
        if drift is None:
            return
        self._timing = (key, now, self.held_schedule(start))
        self._retime(drift)

    def _retime(self, drift: float, *, ground: bool = False) -> None:
        """Our windows moved (``drift`` seconds late; 0: a hold began, they are open to the
        end; ``ground``: still on the ground after half its wait): a new schedule epoch, a
        new version, every peer compares again."""
        self.retimed += 1
        self.ctx.record(
            EventKind.RETIMED,
            Retimed(
                epoch=self.retimed,
                drift_s=round(drift, 1),
                held=drift == 0.0 and not ground,
                on_ground=ground,
            ),
        )
        self._on_retimed()

    def slots(self) -> Slots:
        """The altitude slots the rest of our flight occupies, as the vehicle flies it.  They
        change with the mission, the item flown to and the altitude the vehicle is at (to
        the metre: a slot is 5 m), not with each position report: remembered for those."""
        start, points = self.remaining_flown()
        if len(points) < 2:
            return Slots.of([(self.vehicle.position[2], self.vehicle.position[2])])
        key = (
            self.version,
            self.vehicle.current_item,
            self.vehicle.on_ground,
            round(self.vehicle.relative_alt),
        )
        if self._slots_of is not None and self._slots_of[0] == key:
            return self._slots_of[1]
        schedule = self.held_schedule(start)
        tolerance = self.settings.separation.tolerance
        slots = Slots.of(
            schedule.cruise(k, tolerance) for k in range(start, start + len(points) - 1)
        )
        self._slots_of = (key, slots)
        return slots

    def grid(self, path: list[tuple[int, int]]) -> GridSpec:
        """The comparison grid of a run of ours over ``path``: centred where we are, big
        enough to hold it and the separation around it."""
        lat, lon = self.vehicle.position[:2]
        radius = box_radius_m(
            path, (lat, lon), self.settings.grid_radius_m, self.settings.separation.horizontal_m
        )
        return GridSpec.geo(
            lat, lon, resolution_mm=self.settings.grid_resolution_mm, radius_m=radius
        )

    def near(self, path: list[tuple[int, int]], horizon: int) -> list[tuple[int, int]]:
        """The part of the remaining path a run with this horizon compares (a full run's
        horizon is 0: all of it)."""
        return near_cut(path, horizon, self.vehicle.here(), least=NEAR_SEGMENTS)

    def near_answer(
        self, path: list[tuple[int, int]], horizon: int, segments: int
    ) -> tuple[list[tuple[int, int]], int]:
        """What we answer a near run with: at most the next ``segments`` of ``path`` (the
        size Alice asked for: a run's size on the air shows nothing of our path) and their
        cover of the horizon (:func:`companion.mission.ground.near_answer`)."""
        return near_answer(path, horizon, self.vehicle.here(), segments=segments)
