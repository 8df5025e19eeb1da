"""Which peers a crowded sky compares with now (:meth:`AliceRuns._lazy_s`,
:meth:`AliceRuns._urgent`): all of them while few drones are in range, only those that could
be here within :data:`LAZY_RUNS` first runs once more pairs are in range."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from companion.neighbours.peers import Peer
from companion.runs.alice import LAZY_RUNS, MEASURE_WAIT, AliceRuns

RUN_S = 40.9  # a first run of two segments each with a fresh OT setup, US915 SF7 at 10 % loss
LAZY_S = LAZY_RUNS * RUN_S  # 368 s
INTERVAL_S = 10.0


@dataclass
class _Vehicle:
    on_ground: bool = False


@dataclass
class _Flight:
    segments: int = 3

    def remaining_path(self) -> tuple[int, list[tuple[int, int]]]:
        return 0, [(0, k * 1000) for k in range(self.segments + 1)]

    def grid(self, path: list[tuple[int, int]]) -> None:
        return None


@dataclass
class _Estimates:
    run_s: float = RUN_S

    def seconds(self, m: int, grid: Any, *, fresh: bool, **_: Any) -> float:
        assert (m, fresh) == (2, True)
        return self.run_s


@dataclass
class _Cadence:
    interval_s: float = INTERVAL_S


@dataclass
class _Neighbourhood:
    peers: dict[int, Any]
    meet: dict[int, float] = field(default_factory=dict)
    cadence: _Cadence = field(default_factory=_Cadence)

    def urgency(self, peer: Peer) -> float:
        return self.meet[peer.node]


@dataclass
class _Guard:
    pressed: bool = False

    def pressing(self, peer: Any, slack_s: float) -> bool:
        return self.pressed


def _runs(
    drones: int, *, on_ground: bool = False, pressed: bool = False, run_s: float = RUN_S
) -> AliceRuns:
    runs = AliceRuns.__new__(AliceRuns)  # (only what the choice of peers looks at)
    runs.vehicle = _Vehicle(on_ground)  # type: ignore[assignment]
    runs.flight = _Flight()  # type: ignore[assignment]
    runs.estimates = _Estimates(run_s)  # type: ignore[assignment]
    runs.neighbourhood = _Neighbourhood(dict.fromkeys(range(2, drones + 1)))  # type: ignore[assignment]
    runs.guard = _Guard(pressed)  # type: ignore[assignment]
    return runs


def _peer(node: int, *, measured: bool = True, met_at: float = 0.0) -> Peer:
    peer = Peer.__new__(Peer)
    peer.node, peer.measured, peer.met_at = node, measured, met_at
    return peer


def test_a_few_drones_are_all_compared_a_crowd_is_not() -> None:
    """Four drones have six pairs: every peer is compared as soon as it is heard
    (busy_four_eu868, three_drones, inflight_star as before).  Five drones have ten pairs,
    six fifteen, ten forty-five: a crowd, whatever the link (its runs' length sets how soon
    a peer must be able to be here)."""
    assert _runs(2)._lazy_s() is None
    assert _runs(4)._lazy_s() is None
    for drones in (5, 6, 10):
        assert _runs(drones)._lazy_s() == LAZY_S


def test_a_slow_link_waits_as_many_runs_not_as_many_seconds() -> None:
    """EU868 SF9 at 1 % duty: a first run takes about 40 minutes of duty-cycle budget; a
    crowd there compares any peer that could be here within nine such runs, not within the
    six minutes of US915 SF7 (which would start every run far too late)."""
    slow = 2378.2
    assert _runs(6, run_s=slow)._lazy_s() == LAZY_RUNS * slow


def test_on_the_ground_every_peer_is_compared() -> None:
    """Before take-off the drone waits for its comparisons (hold_for_comparisons): a peer
    left for later would hold it on the ground."""
    assert _runs(10, on_ground=True)._lazy_s() is None


def test_a_crowd_compares_the_peers_that_could_be_here_soon() -> None:
    runs = _runs(10)
    hood = runs.neighbourhood
    hood.meet.update({2: 45.0, 3: LAZY_S, 4: LAZY_S + 1.0, 5: float("inf")})  # type: ignore[attr-defined]
    now = 100.0
    assert runs._urgent(_peer(2), now, LAZY_S)  # closing fast, or a beacon gap: flying at us
    assert runs._urgent(_peer(3), now, LAZY_S)
    assert not runs._urgent(_peer(4), now, LAZY_S)  # a parallel track 800 m off: 400 s at 2 m/s
    assert not runs._urgent(_peer(5), now, LAZY_S)  # flying apart


def test_a_peer_just_met_waits_for_its_second_beacon_unless_that_is_too_late() -> None:
    """Until two beacons give a range rate, the fail-safe's measure is the worst case (every
    drone 800 m off looks 40 s away): a crowd waits for the measurement -- most of
    busy_ten's first runs were parallel tracks taken to fly at each other -- unless a run
    started that much later would come too late (:meth:`Guard.pressing`)."""
    hood_meet = {2: 30.0}
    now = 100.0
    fresh = _peer(2, measured=False, met_at=now - 1.0)
    for pressed in (False, True):
        runs = _runs(10, pressed=pressed)
        runs.neighbourhood.meet.update(hood_meet)  # type: ignore[attr-defined]
        assert runs._urgent(fresh, now, LAZY_S) is pressed
    late = _peer(2, measured=False, met_at=now - MEASURE_WAIT * INTERVAL_S)
    runs = _runs(10)
    runs.neighbourhood.meet.update(hood_meet)  # type: ignore[attr-defined]
    assert runs._urgent(late, now, LAZY_S)  # not measured by now: the worst case decides
