"""A peer's track of plausible positions: what a requester's box is checked against."""

from __future__ import annotations

from companion.mission.levels import Slots
from companion.neighbours.beacon import Beacon
from companion.neighbours.peers import MAX_SPEED_M_S, TRACK_KEPT, TRACK_SLACK_M, Peer
from protocol.messages import Suite

LAT, LON = 474_000_000, 85_450_000
M_PER_E7_LAT = 0.01112  # metres per 1e-7 degree of latitude, near 47.4 N


def north(metres: float) -> tuple[int, int]:
    return LAT + round(metres / M_PER_E7_LAT), LON


def beacon(at: tuple[int, int]) -> Beacon:
    return Beacon(
        at[0], at[1], 518, False, frozenset({Suite.COMPACT}), 7, 1_800_000_000, 1,
        Slots.of([(517.0, 519.0)]),
    )  # fmt: skip


def flown(speed_m_s: float, seconds: int) -> Peer:
    """A peer heard every 10 s flying north at ``speed_m_s``."""
    peer = Peer(9, beacon(north(0)), heard_at=0.0)
    for t in range(0, seconds + 1, 10):
        peer.heard(beacon(north(speed_m_s * t)), float(t), north(-5000))
    return peer


def test_a_request_is_checked_where_the_track_had_it_when_it_began() -> None:
    """Flying north at 15 m/s, heard every 10 s: at t = 120 s it is 1800 m out.  A box made
    at 900 m (t = 60 s, a request that took a minute to arrive whole) is plausible for a
    request that began then, not for one that began now; a point 1 km off its track never."""
    peer = flown(15.0, 120)
    assert peer.anchor == (120.0, north(1800))
    assert peer.plausible_at(north(900), 60.0) and not peer.plausible_at(north(900), 120.0)
    assert not peer.plausible_at((north(900)[0], north(900)[1] + 140_000), 60.0)  # 1 km east
    # at a track point: its slack; 5 s from it, or give or take 5 s, 40 m/s more
    assert peer.plausible_at(north(900 + TRACK_SLACK_M - 1), 60.0)
    assert not peer.plausible_at(north(900 + TRACK_SLACK_M + 1), 60.0)
    further = north(900 + TRACK_SLACK_M + MAX_SPEED_M_S * 5.0 - 1)
    assert peer.plausible_at(further, 60.0, 5.0) and peer.plausible_at(further, 65.0)


def test_an_implausible_jump_joins_no_track_and_the_track_is_bounded() -> None:
    """A beacon 5 km off, 10 s after the last, is no anchor and no track point; the track
    keeps the last TRACK_KEPT plausible positions."""
    peer = flown(10.0, 40)
    peer.heard(beacon(north(5400)), 50.0, north(-5000))
    assert peer.anchor == (40.0, north(400)) and peer.track[-1] == peer.anchor
    assert not peer.plausible_at(north(5400), 50.0)
    long = flown(10.0, 10 * (TRACK_KEPT + 5))
    assert len(long.track) == TRACK_KEPT and long.track[-1] == long.anchor
