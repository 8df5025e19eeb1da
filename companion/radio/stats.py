"""What a link endpoint counts: frames, bytes, airtime and waits each way, drops by reason."""

from __future__ import annotations

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
