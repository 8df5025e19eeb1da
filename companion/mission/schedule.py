"""The flown path in four dimensions: when the drone will be at each vertex, and how high (pure).

The flight model (:mod:`companion.mission.flight_model`) flies the mission on from where the vehicle
is now -- on the ground before take-off, or mid-leg with its speed and current item -- and
every item it reaches gives its vertices of the flown path (:mod:`companion.mission.flightpath`) a
time and an altitude.  A segment's *band* spans the altitudes at its two ends (a leg is a
straight 3-D line: its ramp lies between them; the take-off climb spans the ground to the
take-off altitude) and its *window* runs from reaching its first vertex to leaving its last
(a loiter's time included), each widened by the owner's own uncertainty (:class:`Tolerance`):
its altitude error for the band, and for the window a tolerance that grows with how far ahead
it lies, wider on the late side than on the early one.  A drone still on the ground does not
know exactly when it takes off: its windows start as if it took off now and are widened on
the late side by how long it may still wait there (:attr:`Schedule.wait_s`; the companion
compares again before that runs out, :meth:`companion.mission.own_flight.OwnFlight.keep_time`).  A
drone holding in the air does not know when it flies on: its windows open at the earliest
and stay open (:attr:`Schedule.open_ended`).  These are the volumes its runs compare
(:mod:`protocol.geo.volumes`); :func:`off_schedule` tells when the drone has left them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from companion.mission.flight_model import MAX_PREDICTION_S, Flight, Kinematics
from companion.mission.flightpath import FlightPath
from companion.mission.items import MissionItem
from protocol.geo.volumes import MAX_SEPARATION, Separation, VolumeSpec

PIECE_LAG_S = 20.0  # how far the time at a point of a leg may be from the time its share of
# the leg's length gives: speeding up from a standstill to 15 m/s at 0.73 m/s^2 lags 10.3 s
PIECE_MIN_S = 4 * PIECE_LAG_S  # a leg shorter than this in time is not cut into parts


@dataclass(frozen=True, slots=True)
class Passage:
    """One vertex in 4-D: from when to when the drone is there (seconds from now; ``leave``
    infinite: it stays, or the prediction ended first) and the altitudes it has there (AMSL,
    low and high: a climb in place spans a range)."""

    arrive: float
    leave: float
    low_m: float
    high_m: float
    reached: bool = True  # False: not reached within the prediction (times are bounds)


@dataclass(frozen=True, slots=True)
class Tolerance:
    """The owner's uncertainty about its own flight: altitude (m, either way) and time, in
    seconds: ``rate`` x seconds ahead either way (the model's error), and on top ``late_s``
    later (a hold, a head wind, a slow start: a drone falls behind easily) and ``early_s``
    earlier (nothing makes it fly faster than commanded, but the state a prediction starts
    from -- speed and climb rate from telemetry a moment old -- is off by a few seconds near
    a corner or a climb)."""

    altitude_m: float = 1.0
    late_s: float = 15.0
    early_s: float = 10.0
    rate: float = 0.15
    ground_wait_s: float = math.inf  # on the ground: take-off assumed within this long
    # (it doubles each time the drone has waited half of it and compares again); infinite:
    # when it takes off is not known, its windows stay open until it does

    def late(self, ahead: float) -> float:
        """How much later than predicted the drone may be at a point ``ahead`` s ahead."""
        return self.late_s + self.rate * max(ahead, 0.0)

    def early(self, ahead: float) -> float:
        """How much earlier."""
        return self.early_s + self.rate * max(ahead, 0.0)


@dataclass(frozen=True)
class SeparationSettings:
    """What a conflict is for this drone (its runs use the larger of its own and its peer's
    minima, :class:`protocol.geo.volumes.Separation`): horizontal and vertical separation, and
    its own uncertainty (:class:`Tolerance`).  Defaults: 15 m and 10 m, what a U-plan volume
    generator adds for system error (quoted in ../shared/notes/separation.md; NASA's
    DAIDALUS small-UAS well-clear cylinders are 5-10 m) -- a few metres of GNSS and of PX4's
    track error inside them; times within 15 % of the time ahead either way, the model's
    worst error against PX4 SITL (11 %, docs/autopilot.md), and up to 15 s later or 10 s
    earlier on top (a hold, a head wind; telemetry's age)."""

    horizontal_m: float = 15.0
    vertical_m: float = 10.0
    tolerance: Tolerance = field(default_factory=Tolerance)


@dataclass(frozen=True)
class Schedule:
    """The vertices ``first`` .. of a flown path in 4-D (``passages[j]`` is vertex
    ``first + j``); ``open_ended``: holding in the air, when it flies on is unknown;
    ``wait_s``: on the ground, predicted as if it took off now, and it may wait this much
    longer (infinite: when it takes off is unknown, the windows stay open)."""

    first: int
    passages: tuple[Passage, ...]
    open_ended: bool
    ground_m: float = -math.inf  # home's altitude (AMSL)
    wait_s: float = 0.0

    def band(self, segment: int, tolerance: Tolerance = Tolerance()) -> tuple[float, float]:
        """Lowest and highest altitude (AMSL) segment ``segment`` (of the whole path) flies."""
        a, b = self._ends(segment)
        error = tolerance.altitude_m
        return min(a.low_m, b.low_m) - error, max(a.high_m, b.high_m) + error

    def cruise(self, segment: int, tolerance: Tolerance = Tolerance()) -> tuple[float, float]:
        """The band segment ``segment`` flies *off the ground*: a take-off's or a landing's
        column at its end left out (they lie below the altitudes flown next to them)."""
        a, b = self._ends(segment)
        air = self.ground_m + 0.5
        top_a = a.high_m if a.high_m > air else b.high_m
        top_b = b.high_m if b.high_m > air else a.high_m
        error = tolerance.altitude_m
        return min(top_a, top_b) - error, max(top_a, top_b) + error

    def window(self, segment: int, tolerance: Tolerance = Tolerance()) -> tuple[float, float]:
        """When segment ``segment`` is flown, seconds from now, widened by the tolerance."""
        a, b = self._ends(segment)
        start, end = a.arrive, b.leave
        low = start - tolerance.early(start)
        if self.open_ended or not math.isfinite(end + self.wait_s):
            return low, math.inf
        return low, end + self.wait_s + tolerance.late(end)

    def flown_s(self, segment: int) -> float:
        """Seconds the drone flies segment ``segment``: from leaving its first vertex to
        reaching its last (infinite when it never gets there within the prediction)."""
        a, b = self._ends(segment)
        return b.arrive - a.leave

    def piece_window(
        self,
        segment: int,
        part: tuple[float, float],
        tolerance: Tolerance = Tolerance(),
        lag_s: float = PIECE_LAG_S,
    ) -> tuple[float, float]:
        """When the part ``part`` (from and to, shares of its length) of segment ``segment``
        is flown, widened by the tolerance: the segment's window, cut where the time its
        share of the leg gives -- flown from leaving its first vertex to reaching its last --
        is ``lag_s`` (the most a speed-up or a slow-down puts the drone off that time) and
        the tolerance away.  Within the segment's window; the parts of a segment cover it."""
        low, high = self.window(segment, tolerance)
        a, _ = self._ends(segment)
        span = self.flown_s(segment)
        if not math.isfinite(span) or self.open_ended:
            return low, high
        start, end = part
        if start > 0.0:
            t = a.leave + start * span - lag_s
            low = max(low, t - tolerance.early(t))  # (t - early(t) grows with t)
        if end < 1.0 and math.isfinite(high):
            t = a.leave + end * span + lag_s
            high = min(high, t + self.wait_s + tolerance.late(t))
        return low, high

    def _ends(self, segment: int) -> tuple[Passage, Passage]:
        j = segment - self.first
        if not 0 <= j < len(self.passages) - 1:
            raise IndexError(f"segment {segment} is not on the scheduled path")
        return self.passages[j], self.passages[j + 1]


@dataclass(frozen=True, slots=True)
class Vehicle:
    """What the companion knows of its vehicle now: where (degrees, metres above home),
    how fast, which item it flies to, whether it is on the ground."""

    lat: float
    lon: float
    alt: float
    speed_m_s: float
    current: int
    on_ground: bool
    loitering_s: float = 0.0  # over the current item's point this long (its hold under way)
    climb_m_s: float = 0.0  # vertical speed, up
    held: bool = False  # holding in the air: when it flies on is unknown
    wait_s: float = math.inf  # on the ground: it takes off within this long


def predict(
    path: FlightPath,
    items: list[MissionItem],
    home: tuple[float, float, float],
    first: int,
    vehicle: Vehicle,
    kinematics: Kinematics,
    *,
    home_is_item0: bool = False,
    limit_s: float = MAX_PREDICTION_S,
) -> Schedule:
    """The schedule of the path's vertices from ``first`` on (the start of the leg under way),
    the mission flown on by the model from the vehicle's state (for ``limit_s`` seconds at
    most: vertices not reached by then are not :attr:`Passage.reached`)."""
    flight = Flight(kinematics, home, list(items), home_is_item0)
    flight.lat, flight.lon, flight.alt = vehicle.lat, vehicle.lon, max(vehicle.alt, 0.0)
    flight.current = min(max(vehicle.current, 0), max(len(items) - 1, 0))
    if not vehicle.on_ground:  # (held: as if it flew on now, the earliest it can)
        flight.armed = flight.flying = flight.mission_running = True
        flight.speed, flight.vz = vehicle.speed_m_s, vehicle.climb_m_s
        flight.loitering(vehicle.loitering_s)
    reached = flight.predict(limit_s=limit_s)
    by_item: dict[int, list[tuple[float, float, float]]] = {}
    for r in reached:
        by_item.setdefault(r.item, []).append(
            (r.t, math.inf if r.left is None else r.left, home[2] + r.alt)
        )
    here = home[2] + max(vehicle.alt, 0.0)
    passages: list[Passage] = []
    last = 0.0
    for k in range(first, len(path.vertices)):
        visits = [v for i in path.vertices[k].items for v in by_item.get(i, [])]
        alts = [alt for *_, alt in visits]
        if k == first:  # where the leg under way started: the drone is past it, now
            arrive, leave = 0.0, max((t for _, t, _ in visits), default=0.0)
            alts.append(here)
            if vehicle.on_ground:
                alts.append(home[2])
        elif visits:
            arrive, leave = min(t for t, _, _ in visits), max(t for _, t, _ in visits)
        else:  # not reached in the prediction (after a loiter without end, a limit)
            arrive, leave = last, math.inf
            alts = alts or [passages[-1].high_m]
        last = max(last, arrive if math.isfinite(arrive) else last)
        passages.append(Passage(arrive, leave, min(alts), max(alts), bool(visits) or k == first))
    wait = vehicle.wait_s if vehicle.on_ground else 0.0
    return Schedule(first, tuple(passages), vehicle.held and not vehicle.on_ground, home[2], wait)


def off_schedule(
    before: Schedule, before_s: float, now: Schedule, now_s: float, tolerance: Tolerance
) -> float | None:
    """How far the drone has fallen behind (a hold, wind: positive seconds) or run ahead of
    ``before`` (predicted at ``before_s``; ``now`` at ``now_s``, both on one clock) at the
    first vertex still ahead where that is more than half the tolerance its windows are
    widened with; None when it is within it everywhere.  Windows compared since ``before``
    were predicted within half a tolerance of it; so until this answers, every window a peer
    holds is off by less than its tolerance, and the other half leaves time to compare again
    before it matters."""
    for j, passage in enumerate(now.passages[1:], start=now.first + 1):
        i = j - before.first
        if not (passage.reached and 0 <= i < len(before.passages)):
            continue
        then = before.passages[i]
        if not then.reached:
            continue
        drift = (now_s + passage.arrive) - (before_s + then.arrive)
        allowed = tolerance.late(passage.arrive) if drift > 0 else tolerance.early(passage.arrive)
        if abs(drift) > allowed / 2:
            return drift
    return None


Z_RANGE_M = 20_000.0  # every band within +-20 km: any altitude (the public range tells nothing)
T_RANGE_S = 18 * 3600  # every window within 18 h of the run's epoch


def run_volumes(settings: SeparationSettings, resolution_mm: int, epoch_s: int) -> VolumeSpec:
    """The public volume parameters of a run on a grid of ``resolution_mm`` (its hello's, or
    a peer's minima in a first reply): separations rounded up to whole cells, the horizontal
    one widened by the grid's own error -- each vertex is snapped to its cell, up to half a
    diagonal away, so two segments' distance on the grid is within sqrt(2) cells of the
    true one; the run then never misses a pair closer than ``horizontal_m``."""
    cells = 1000.0 / resolution_mm
    snapped = math.sqrt(2.0) if settings.horizontal_m > 0 else 0.0
    separation = Separation(
        min(math.ceil(settings.horizontal_m * cells + snapped), MAX_SEPARATION),
        min(math.ceil(settings.vertical_m * cells), MAX_SEPARATION),
    )
    return VolumeSpec(separation, math.ceil(Z_RANGE_M * cells), T_RANGE_S, epoch_s)


def route_volumes(
    schedule: Schedule,
    first: int,
    count: int,
    resolution_mm: int,
    since_epoch_s: float,
    tolerance: Tolerance,
    cover: Mapping[int, tuple[float, float]] | None = None,
) -> tuple[tuple[tuple[int, int], ...], tuple[tuple[int, int], ...]]:
    """Bands (grid cells, rounded outwards) and windows (whole seconds after the run's epoch,
    rounded outwards; open-ended ones to the end of the time range) of segments ``first`` ..
    ``first + count - 1``; ``since_epoch_s``: how long ago the epoch was; ``cover``: altitudes
    (AMSL, low and high) a segment's band spans as well (Alice's raises as she flies them:
    :meth:`companion.mission.own_flight.OwnFlight.reaches`)."""
    whole = [(k, 0.0, 1.0) for k in range(first, first + count)]
    return piece_volumes(schedule, whole, resolution_mm, since_epoch_s, tolerance, cover)


Piece = tuple[int, float, float]  # a segment, and the part of it (from, to: shares of its length)


def split_long(schedule: Schedule, first: int, count: int, slots: int) -> list[Piece]:
    """Segments ``first`` .. ``first + count - 1`` in up to ``slots`` parts: while slots are
    left, the part flown longest is halved (none shorter than :data:`PIECE_MIN_S`, none of
    a drone holding in the air).  A run is padded to its public size anyway: its free
    slots cost nothing, and a part's window is its own stretch of the leg's -- a drone that
    crosses a 5 km leg a minute after us is no conflict, the window of the whole leg made it
    one (busy_ten's false alarms)."""
    pieces: list[Piece] = [(k, 0.0, 1.0) for k in range(first, first + count)]
    if schedule.open_ended:
        return pieces
    while len(pieces) < slots:
        flown = [schedule.flown_s(k) * (end - start) for k, start, end in pieces]
        j = max(range(len(pieces)), key=flown.__getitem__)
        if not PIECE_MIN_S <= flown[j] < math.inf:
            break
        k, start, end = pieces[j]
        middle = (start + end) / 2
        pieces[j : j + 1] = [(k, start, middle), (k, middle, end)]
    return pieces


def piece_volumes(
    schedule: Schedule,
    pieces: list[Piece],
    resolution_mm: int,
    since_epoch_s: float,
    tolerance: Tolerance,
    cover: Mapping[int, tuple[float, float]] | None = None,
) -> tuple[tuple[tuple[int, int], ...], tuple[tuple[int, int], ...]]:
    """:func:`route_volumes` of parts of segments (:func:`split_long`): each part its
    segment's band and its own window (:meth:`Schedule.piece_window`)."""
    cells = 1000.0 / resolution_mm
    bands, windows = [], []
    for k, start, end in pieces:
        low, high = schedule.band(k, tolerance)
        if cover is not None and k in cover:
            low, high = min(low, cover[k][0]), max(high, cover[k][1])
        bands.append((math.floor(low * cells), math.ceil(high * cells)))
        first, last = schedule.piece_window(k, (start, end), tolerance)
        last = last + since_epoch_s if math.isfinite(last) else T_RANGE_S
        windows.append((math.floor(first + since_epoch_s), min(math.ceil(last), T_RANGE_S)))
    return tuple(bands), tuple(windows)
