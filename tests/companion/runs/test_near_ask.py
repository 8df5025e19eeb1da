"""How many of the peer's segments a near run asks for (:meth:`AliceRuns._near_ask`): four
when even queued behind the first runs the channel still carries (:meth:`AliceRuns._first_runs`)
that run comes in time, else as many as we compare."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from companion.runs.alice import NEAR_ASK, NEAR_SLACK, AliceRuns
from companion.runs.failsafe import FailsafeSettings

RUN_2X2_S = 39.3  # fresh OT setup, EU868 SF7 at 10 % loss (as estimated in busy_four_eu868)
RUN_2X4_S = 52.9


@dataclass
class _Vehicle:
    on_ground: bool = False


@dataclass
class _Flight:
    def remaining_path(self) -> tuple[int, list[tuple[int, int]]]:
        return 0, [(0, 0), (0, 1000), (0, 2000)]  # two segments: m = 2

    def grid(self, path: list[tuple[int, int]]) -> None:
        return None


class _Estimates:
    def seconds(self, m: int, grid: Any, *, fresh: bool, n: int | None = None, **_: Any) -> float:
        assert m == 2 and fresh
        return RUN_2X4_S if n == 4 else RUN_2X2_S


@dataclass
class _Endpoint:
    channels: int = 1


@dataclass
class _Peer:
    node: int
    size: int = 4
    near_run: tuple[float, int] | None = None
    alice: bool = True  # we are its Alice


@dataclass
class _Neighbourhood:
    peers: dict[int, _Peer]
    meet: float = 300.0

    def urgency(self, peer: Any) -> float:
        return self.meet


class _Standing:
    def pending(self, peer: _Peer) -> bool:
        return peer.alice


@dataclass
class _Settings:
    failsafe: FailsafeSettings = field(default_factory=FailsafeSettings)


def _runs(peers: list[_Peer], *, channels: int = 1, on_ground: bool = False) -> AliceRuns:
    runs = AliceRuns.__new__(AliceRuns)  # (only what the ask looks at)
    runs.vehicle = _Vehicle(on_ground)  # type: ignore[assignment]
    runs.flight = _Flight()  # type: ignore[assignment]
    runs.estimates = _Estimates()  # type: ignore[assignment]
    runs.endpoint = _Endpoint(channels)  # type: ignore[assignment]
    runs.neighbourhood = _Neighbourhood({p.node: p for p in peers})  # type: ignore[assignment]
    runs.standing = _Standing()  # type: ignore[assignment]
    runs.settings = _Settings()  # type: ignore[assignment]
    return runs


PATH = [(0, 0), (0, 1000), (0, 2000)]


def test_first_runs_count_the_pairs_in_range_we_have_not_compared() -> None:
    """Four drones in flight, none compared yet: six first runs take turns on the channel.
    Three drones (inflight_star), one of our two peers compared: half of three pairs.  A
    peer we are Bob for is not ours to count (its Alice counts it)."""
    assert _runs([_Peer(2), _Peer(3), _Peer(4)])._first_runs() == 6.0
    assert _runs([_Peer(2, near_run=(0.0, 900)), _Peer(3)])._first_runs() == 1.5
    assert _runs([_Peer(2, alice=False), _Peer(3)])._first_runs() == 3.0
    assert _runs([_Peer(2)])._first_runs() == 1.0  # two drones: the run alone


def test_first_runs_do_not_queue_where_runs_do_not_take_turns() -> None:
    """Several channels (runs of different pairs proceed in parallel), the ground (nothing
    is urgent there), nothing left to compare as Alice, and a crowded sky (five drones or
    more: only the urgent peers are compared, :meth:`AliceRuns._lazy_s`)."""
    four = [_Peer(2), _Peer(3), _Peer(4)]
    assert _runs(four, channels=8)._first_runs() == 1.0
    assert _runs(four, on_ground=True)._first_runs() == 1.0
    assert _runs([_Peer(2, alice=False), _Peer(3, alice=False)])._first_runs() == 1.0
    assert _runs([_Peer(k) for k in range(2, 7)])._first_runs() == 1.0


def test_a_near_run_asks_four_only_when_it_comes_in_time_queued() -> None:
    """A 2 x 4 first run (52.9 s, 58.2 s with the slack) behind five others would end
    after a meeting 300 s off: it asks two and leaves the channel to the others; alone, or
    with a meeting far enough off, it asks four."""
    crowded = _runs([_Peer(2), _Peer(3), _Peer(4)])
    peer = crowded.neighbourhood.peers[2]
    assert crowded._near_ask(PATH, peer, None, fresh=True) == 2  # type: ignore[arg-type]
    margin = FailsafeSettings().margin_s
    crowded.neighbourhood.meet = 6 * RUN_2X4_S * NEAR_SLACK + margin + 1.0  # type: ignore[attr-defined]
    assert crowded._near_ask(PATH, peer, None, fresh=True) == NEAR_ASK  # type: ignore[arg-type]
    alone = _runs([_Peer(2)])
    assert alone._near_ask(PATH, alone.neighbourhood.peers[2], None, fresh=True) == NEAR_ASK  # type: ignore[arg-type]


def test_a_near_run_never_asks_more_than_the_peer_has() -> None:
    runs = _runs([_Peer(2, size=2)])
    assert runs._near_ask(PATH, runs.neighbourhood.peers[2], None, fresh=True) == 2  # type: ignore[arg-type]
