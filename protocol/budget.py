"""Limits on repeated runs per peer: the mitigation of the paper's probing attack.

Alice learns one bit per segment per run.  With many short segments and many runs she could
sweep the plane and trace Bob's path (section IV of the paper discusses the dense-grid probe).
Bob therefore caps the segments per run (:class:`~protocol.intersection.Limits`) and the runs
per peer in a sliding window (:class:`RunBudget`).  Sans-IO: the caller passes the time.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from .errors import LocalProtocolError


class BudgetExceededError(LocalProtocolError):
    """This peer has used up its runs for the current window."""


@dataclass
class RunBudget:
    """At most ``max_runs`` runs per peer within any ``window_s`` seconds."""

    max_runs: int = 6
    window_s: float = 3600.0
    _runs: dict[bytes, deque[float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.max_runs < 1 or self.window_s <= 0:
            raise LocalProtocolError("a run budget needs max_runs >= 1 and window_s > 0")

    def remaining(self, peer: bytes, now: float) -> int:
        runs = self._runs.get(peer, deque())
        while runs and runs[0] <= now - self.window_s:
            runs.popleft()
        return self.max_runs - len(runs)

    def admit(self, peer: bytes, now: float) -> None:
        """Record a run for ``peer`` at time ``now`` or raise :class:`BudgetExceededError`."""
        if self.remaining(peer, now) <= 0:
            raise BudgetExceededError(
                f"peer {peer.hex()} already ran {self.max_runs} times in {self.window_s:.0f} s"
            )
        self._runs.setdefault(peer, deque()).append(now)
