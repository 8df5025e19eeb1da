"""What a link endpoint counts: frames, bytes, airtime and waits each way, drops by reason."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field


@dataclass
class LinkStats:
    frames_sent: int = 0
    frames_retransmitted: int = 0
    polls_sent: int = 0
    acks_sent: int = 0
    bytes_sent: int = 0
    airtime_s: float = 0.0
    duty_wait_s: float = 0.0
    frames_received: int = 0
    bytes_received: int = 0  # frames addressed to us, headers included
    messages_sent: int = 0
    messages_received: int = 0
    dropped: dict[str, int] = field(default_factory=dict)

    def drop(self, reason: str) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1


class ChannelUse:
    """How much of the last seconds the channel carried frames we heard or sent (any kind:
    beacons, runs, ACKs): a public measure of how loaded the channel is.  Frames lost to
    collisions go unheard, so it is a lower bound."""

    def __init__(self, horizon_s: float) -> None:
        self.horizon_s = horizon_s
        self._frames: deque[tuple[float, float]] = deque()  # (ended at, seconds on the air)

    def add(self, ended_at: float, airtime_s: float) -> None:
        self._frames.append((ended_at, airtime_s))
        while self._frames and self._frames[0][0] < ended_at - self.horizon_s:
            self._frames.popleft()

    def share(self, now: float, window_s: float) -> float:
        """Share of the last ``window_s`` (at most :attr:`horizon_s`) on the air, 0..1."""
        window = min(window_s, self.horizon_s)
        if window <= 0:
            return 0.0
        since = now - window
        busy = sum(min(air, end - since) for end, air in self._frames if end > since)
        return min(busy / window, 1.0)
