"""What a companion knows about each peer it hears (pure): beacons, speed, urgency, reach.

Distances are on the local tangent plane (:func:`protocol.geo.geodesy.ground_offset`, WGS84); speeds
come from successive beacons.  Urgency (:func:`time_to_meet`) comes from the rate at which
the distance shrinks, beacon to beacon, or, without a fresh measurement, from the worst case:
the two drones flying straight at each other, never below ``floor_m_s`` each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from companion.mission.ground import distance_m
from companion.neighbours.beacon import Beacon
from companion.roles import Phase, Role
from protocol.run import DEFAULT_LIMITS

TRACK_KEPT = 32  # plausible positions kept per peer (its track: minutes of beacons)
MAX_SPEED_M_S = 40.0  # no drone flies faster: beacon speeds are capped, boxes bounded by it
TRACK_SLACK_M = 200.0  # position error a track allows on top of MAX_SPEED_M_S
# What a run compared (companion.runs.standing.Standing.versions): the peer's mission version,
# ours as planned, and our raises (segment, metres) that come near the peer's altitudes
Versions = tuple[int, int, frozenset[tuple[int, float]]]


def _reach_m(seconds: float) -> float:
    """How far from a plausible position a drone may plausibly be ``seconds`` from it."""
    return TRACK_SLACK_M + MAX_SPEED_M_S * seconds


@dataclass
class Peer:
    node: int
    beacon: Beacon
    heard_at: float
    identity: bytes = b""  # the certified drone's fingerprint (companion.neighbours.registry)
    speed_m_s: float = 0.0
    role: Role | None = None  # once this pair has met: roles then stay
    compared: Versions | None = None  # what the last run compared (Standing.versions)
    next_try: float = 0.0
    recheck_at: float = math.inf  # we hold for it: compare again from then on (same versions)
    retry_in: float | None = None  # after a run without result: retry this soon (None: the
    # settings' retry_after_s)
    busy: bool = False  # it refused our last request BUSY: asked again soon
    raised: bool = False  # its announced altitude slots once reached above its first ones
    conflicts: set[int] = field(default_factory=set)  # our segments that meet its path
    plan: list[tuple[Phase, int]] = field(default_factory=list)  # runs still to do (phase, horizon)
    plan_version: Versions | None = None  # the versions the plan was made for
    covered: set[int] = field(default_factory=set)  # our segments a finished run compared
    settled: set[int] = field(default_factory=set)  # ... for good: a full run compared
    # them, or we leave them before the peer could come near (a near run left them out)
    full_after: float = 0.0  # link time before which the full run waits
    full_left: bool = False  # the last full run compared only the urgent part: more to do
    near_run: tuple[float, int] | None = None  # the last near run: (started at, horizon m)
    rate_from: tuple[float, tuple[int, int], float] | None = None  # (when, where, distance
    # to us): the beacon speed and range rate are measured from
    range_rate: float = 0.0  # m/s, positive while we fly apart
    measured: bool = False  # range_rate comes from two beacons
    made_at: float | None = None  # link time its beacon's position was taken (its stamp)
    met_at: float = 0.0  # link time it became a peer
    # (link time, position) of its last TRACK_KEPT positions that its track makes plausible,
    # oldest first: each within TRACK_SLACK_M plus MAX_SPEED_M_S since the one before.  A
    # run's box is checked against them (companion.runs.bob), not against a claim out of
    # nowhere.
    track: list[tuple[float, tuple[int, int]]] = field(default_factory=list)

    @property
    def size(self) -> int:
        """The padded size of the peer's path, from its beacon's size class (what its runs
        show)."""
        return DEFAULT_LIMITS.public_size(1 << self.beacon.size_class)

    @property
    def position(self) -> tuple[int, int]:
        return self.beacon.lat, self.beacon.lon

    def heard(
        self,
        beacon: Beacon,
        now: float,
        own: tuple[int, int],
        *,
        max_speed: float = MAX_SPEED_M_S,
        made_at: float | None = None,
    ) -> None:
        """A new beacon: update the speed estimate (smoothed, capped: a take-off jump is not
        a speed) and the rate at which the distance to us changes -- each over at least
        ``RATE_SPAN_S``: two beacons a second apart (one sent at once after an edit) and a
        position of ours a moment old would make a closing rate out of nothing -- and the
        position.  ``made_at``: when the beacon's position was taken (its time stamp, in
        link time), else when it was heard -- a beacon queued behind a run's burst is heard
        many seconds late, and two positions 14 s apart heard 4 s apart are not 3.5 times
        the speed."""
        made = now if made_at is None else min(made_at, now)
        gap = distance_m(own, (beacon.lat, beacon.lon))
        if self.rate_from is None:  # our distance at its first beacon is not known
            self.rate_from = (made, (beacon.lat, beacon.lon), gap)
        then, where, before = self.rate_from
        dt = made - then
        if dt >= RATE_SPAN_S:
            speed = min(distance_m(where, (beacon.lat, beacon.lon)) / dt, max_speed)
            self.speed_m_s = speed if self.speed_m_s == 0 else 0.5 * (self.speed_m_s + speed)
            self.range_rate = (gap - before) / dt
            self.measured = True
            self.rate_from = (made, (beacon.lat, beacon.lon), gap)
        self.beacon, self.heard_at, self.made_at = beacon, now, made
        here = (beacon.lat, beacon.lon)
        if self.anchor is None or distance_m(self.anchor[1], here) <= self.reach_m(made):
            self.track = [*self.track[1 - TRACK_KEPT :], (made, here)]

    @property
    def anchor(self) -> tuple[float, tuple[int, int]] | None:
        """Its last plausible position (link time, position), None before any."""
        return self.track[-1] if self.track else None

    def reach_m(self, now: float) -> float:
        """How far from its anchor it may plausibly be at ``now`` (link time)."""
        if self.anchor is None:
            return 0.0
        return _reach_m(max(now - self.anchor[0], 0.0))

    def plausible_at(self, point: tuple[int, int], when: float, within_s: float = 0.0) -> bool:
        """Whether it may have been at ``point`` at link time ``when`` (give or take
        ``within_s``): within TRACK_SLACK_M plus MAX_SPEED_M_S of the plausible position of
        its track nearest that time."""
        if not self.track:
            return False
        made, where = min(self.track, key=lambda anchor: abs(anchor[0] - when))
        return distance_m(point, where) <= _reach_m(abs(when - made) + within_s)

    def position_age(self, now: float) -> float:
        """Seconds since its position was taken."""
        return max(now - (self.heard_at if self.made_at is None else self.made_at), 0.0)


RATE_SPAN_S = 4.0  # speeds and range rates are measured over at least this long
SEPARATING_M_S = 2.0  # a range rate above this: the two fly apart
MIN_CLOSING_M_S = 2.0  # a measured closing rate is taken as at least this
FRESH_S = 20.0  # a range rate older than this is not trusted: the longest gap between two
# beacons sent at the default 10 s interval (1.3 intervals of jitter, half an interval deferred
# behind a run's frames) and 2 s -- at 15 s one beacon in ten came after its measurement had
# lapsed (busy_ten), and the fail-safe took a parallel track 800 m off for one flying at us


def time_to_meet(
    own: tuple[int, int],
    own_speed: float,
    peer: Peer,
    *,
    floor_m_s: float,
    peer_floor_m_s: float | None = None,
    now: float | None = None,
    silent_after_s: float = 0.0,
    measured: bool = True,
) -> float:
    """Seconds until the two drones could meet.  With a fresh measurement (two beacons, the
    last one less than ``FRESH_S`` old; a turn shows within one interval) at the rate their
    distance shrinks, at least ``MIN_CLOSING_M_S``; otherwise flying straight at each other,
    each at least ``floor_m_s`` (the peer ``peer_floor_m_s`` if given); a peer not heard
    for more than ``silent_after_s`` (longer than beacons are ever deferred) already that
    much closer for every second since (a peer that fell silent is not parked where it
    was).  Infinite while they clearly fly apart.  ``measured=False``: the worst case even
    with a measurement (the earliest the peer *could* be here)."""
    fresh = measured and peer.measured and (now is None or now - peer.heard_at <= FRESH_S)
    if fresh and peer.range_rate > SEPARATING_M_S:
        return math.inf
    distance = distance_m(own, peer.position)
    if fresh:
        closing = max(-peer.range_rate, MIN_CLOSING_M_S)
    else:
        peer_speed = max(peer.speed_m_s, floor_m_s if peer_floor_m_s is None else peer_floor_m_s)
        closing = max(own_speed, floor_m_s) + peer_speed
        if now is not None and now - peer.heard_at > silent_after_s:
            distance = max(distance - peer_speed * (now - peer.heard_at), 0.0)
    return distance / closing
