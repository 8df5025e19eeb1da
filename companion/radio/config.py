"""The link endpoint's tunables and its per-session state (:mod:`.endpoint` drives them)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, field

from companion.radio.airtime import LinkProfile
from companion.radio.arq import LinkError, PeerAborted


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """Tunables of the link; defaults suit every profile."""

    max_message: int = 1 << 20
    window: int = 64
    max_tries: int = 24
    max_polls: int = 20
    max_partial: int = 8
    max_sessions: int = 32
    control_reserve: float = 0.1
    latency_allowance_s: float = 0.05
    idle_timeout_s: float | None = None  # None: derived from the profile
    # channels of the region used (at most the profile's): 1, everything on the one channel;
    # more, beacons and each session's call on channel 0, the rest of a session on its
    # responder's channel (1..channels-1, from the responder's node id)
    channels: int = 1

    def idle_timeout(self, profile: LinkProfile) -> float:
        """How long silence from a peer is tolerated.  On a duty-cycled link a peer that spent
        its budget is silent for up to a window, and lost frames stretch that: three windows."""
        if self.idle_timeout_s is not None:
            return self.idle_timeout_s
        return 3 * profile.duty_window_s + 600.0 if profile.duty_cycle else 300.0


@dataclass
class Session:
    """One session of the endpoint: its peer and id, inbox, send lock and state."""

    peer: int
    session: int
    last_heard: float
    inbox: asyncio.Queue[bytes | LinkError] = field(default_factory=asyncio.Queue)
    send_lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    next_seq: int = 0
    aborted: PeerAborted | None = None
    arrived: float = 0.0  # accepted sessions: when the first fragment of the first message came
    # A keyed session (:meth:`LinkEndpoint.secure`): an ABORT ends it only with a proof this
    # says is the peer's; without one it is ignored (anybody can put an ABORT on the air).
    abort_check: Callable[[int, bytes], bool] | None = None
    lingering: bool = False  # a finished run kept open to answer a late copy (``linger``)
    channel: int = 0  # its own channel (several channels): once ``moved``, all of it is there
    moved: bool = False  # its first message is through: the session is on its own channel
    listen_on: int = 0  # before that: where its opener listens (its last probe's channel)
    probes: int = 0
    ours: bool = False  # we opened it
    accepted: bool = True  # handed to ``accept`` (a call waits for its first message)

    def hears_on(self) -> int:
        """Where the radio listens for it: its channel once moved, else its last probe's."""
        return self.channel if self.moved else self.listen_on
