"""When Alice starts a run on one channel: not into other pairs' runs, nor into a storm of
beacons that her first frame would wait behind (:meth:`AliceRuns._channel_ours`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from companion.runs.alice import LOAD_MAX, QUIET_CYCLES, AliceRuns


@dataclass
class _Endpoint:
    quiet_s: float
    share: float
    channels: int = 1
    cycle_s: float = 0.5

    def others_quiet_s(self) -> float:
        return self.quiet_s

    def load(self, window_s: float) -> float:
        return self.share


@dataclass
class _Vehicle:
    on_ground: bool = False


@dataclass
class _Guard:
    urgent: bool = False

    def pressing(self, peer: Any, slack_s: float) -> bool:
        return self.urgent


def _runs(endpoint: _Endpoint, *, urgent: bool = False) -> AliceRuns:
    runs = AliceRuns.__new__(AliceRuns)  # (only what the channel's turn looks at)
    runs.endpoint = endpoint  # type: ignore[assignment]
    runs.vehicle = _Vehicle()  # type: ignore[assignment]
    runs.guard = _Guard(urgent)  # type: ignore[assignment]
    runs._quiet_need = None
    return runs


CYCLE_S = _Endpoint.cycle_s
LONG_QUIET = QUIET_CYCLES[1] * CYCLE_S + 1.0  # longer than any quiet a run waits for


def test_a_quiet_lightly_loaded_channel_is_ours() -> None:
    assert _runs(_Endpoint(quiet_s=LONG_QUIET, share=0.2))._channel_ours(None)  # type: ignore[arg-type]
    assert _runs(_Endpoint(quiet_s=float("inf"), share=0.0))._channel_ours(None)  # type: ignore[arg-type]


def test_no_run_starts_into_a_loaded_channel_unless_it_is_pressing() -> None:
    """At the start of busy_ten nine runs began within 20 s while beacons filled the channel
    (no run yet on the air to defer to); their first frames waited 19-54 s behind the beacons
    and then shared the channel, the first result at 260 s."""
    storm = _Endpoint(quiet_s=float("inf"), share=LOAD_MAX + 0.1)
    assert not _runs(storm)._channel_ours(None)  # type: ignore[arg-type]
    assert _runs(storm, urgent=True)._channel_ours(None)  # type: ignore[arg-type]
    assert _runs(_Endpoint(quiet_s=float("inf"), share=LOAD_MAX - 0.1))._channel_ours(None)  # type: ignore[arg-type]


def test_no_run_starts_right_after_another_pairs_frame() -> None:
    just_heard = _Endpoint(quiet_s=QUIET_CYCLES[0] * CYCLE_S - 0.1, share=0.1)
    assert not _runs(just_heard)._channel_ours(None)  # type: ignore[arg-type]
    assert _runs(just_heard, urgent=True)._channel_ours(None)  # type: ignore[arg-type]
