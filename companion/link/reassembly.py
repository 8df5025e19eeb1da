"""Receiving side of the link: reassembly, duplicate suppression, acknowledgements (pure).

Fragments are stored as they arrive (nothing is allocated from a claimed size), so a forged
``count`` costs nothing.  A message is delivered once, when its last missing fragment arrives;
later copies of its fragments or polls are answered with a COMPLETE acknowledgement from a
short memory of finished messages.  Partial messages that hear nothing for ``idle_timeout``
seconds are dropped and their memory freed.
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass, field

from .frames import AckInfo, Flag, Frame, FrameType

Key = tuple[int, int, int]  # (source node, session, message seq)


@dataclass(frozen=True, slots=True)
class Delivered:
    src: int
    session: int
    seq: int
    data: bytes


@dataclass
class _Partial:
    count: int
    last_heard: float
    epoch: int = field(default_factory=lambda: secrets.randbelow(255) + 1)
    fragments: dict[int, bytes] = field(default_factory=dict)
    size: int = 0


@dataclass
class ReceiverStats:
    delivered: int = 0
    duplicates: int = 0
    expired: int = 0
    refused: dict[str, int] = field(default_factory=dict)

    def refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1


class Receiver:
    """Turns DATA and POLL frames addressed to ``node`` into messages and ACK frames."""

    def __init__(
        self,
        node: int,
        *,
        max_message: int = 1 << 20,
        max_partial: int = 8,
        idle_timeout: float = 120.0,
    ) -> None:
        self.node = node
        self.max_message = max_message
        self.max_partial = max_partial
        self.idle_timeout = idle_timeout
        self.stats = ReceiverStats()
        self._partial: dict[Key, _Partial] = {}
        self._done: dict[Key, tuple[int, float]] = {}  # key -> (count, finished at)

    @property
    def buffered_bytes(self) -> int:
        return sum(p.size for p in self._partial.values())

    def pending(self) -> int:
        return len(self._partial)

    def on_frame(self, frame: Frame, now: float) -> tuple[Delivered | None, Frame | None]:
        """Consume one DATA or POLL frame; return (message completed, ACK frame to send)."""
        key = (frame.src, frame.session, frame.seq)
        if key in self._done:
            count, _ = self._done[key]
            self._done[key] = (count, now)
            if frame.type is FrameType.DATA:
                self.stats.duplicates += 1
            if frame.count != count:
                self.stats.refuse("inconsistent")
                return None, None
            return None, self._ack(frame, AckInfo(count), Flag.COMPLETE)
        partial = self._partial.get(key)
        if frame.type is FrameType.POLL:
            if partial is None:
                return None, self._ack(frame, AckInfo(0))
            partial.last_heard = now  # the sender is alive: keep what we have
            return None, self._ack(frame, self._info(partial))
        if partial is None:
            if frame.index < frame.count - 1 and (frame.count - 1) * len(frame.payload) >= (
                self.max_message
            ):
                self.stats.refuse("too_large")  # its claimed size alone is over the limit
                return None, None
            if len(self._partial) >= self.max_partial:
                self.expire(now)
            if len(self._partial) >= self.max_partial:
                self.stats.refuse("too_many_partial")
                return None, None
            partial = self._partial[key] = _Partial(frame.count, now)
        if frame.count != partial.count:
            self.stats.refuse("inconsistent")
            return None, None
        partial.last_heard = now
        if frame.index in partial.fragments:
            self.stats.duplicates += 1
        else:
            if partial.size + len(frame.payload) > self.max_message:
                del self._partial[key]
                self.stats.refuse("too_large")
                return None, None
            partial.fragments[frame.index] = frame.payload
            partial.size += len(frame.payload)
        delivered = None
        if len(partial.fragments) == partial.count:
            del self._partial[key]
            data = b"".join(partial.fragments[i] for i in range(partial.count))
            self._done[key] = (partial.count, now)
            self.stats.delivered += 1
            delivered = Delivered(frame.src, frame.session, frame.seq, data)
            return delivered, self._ack(frame, AckInfo(partial.count), Flag.COMPLETE)
        if frame.flags & Flag.ACK_REQ:
            return None, self._ack(frame, self._info(partial))
        return None, None

    @staticmethod
    def _info(partial: _Partial) -> AckInfo:
        return AckInfo.of(set(partial.fragments), partial.count, partial.epoch)

    def _ack(self, frame: Frame, info: AckInfo, flags: Flag = Flag.NONE) -> Frame:
        return Frame(
            FrameType.ACK,
            self.node,
            frame.src,
            frame.session,
            frame.seq,
            0,
            frame.count,
            info.encode(),
            flags,
        )

    def expire(self, now: float) -> int:
        """Free partial messages idle for ``idle_timeout`` and forget old finished ones."""
        stale = [k for k, p in self._partial.items() if now - p.last_heard >= self.idle_timeout]
        for key in stale:
            del self._partial[key]
        self.stats.expired += len(stale)
        old = [k for k, (_, t) in self._done.items() if now - t >= self.idle_timeout]
        for key in old:
            del self._done[key]
        return len(stale)

    def forget_session(self, src: int, session: int) -> None:
        """Free the partial messages of a session that ended or was aborted.  Finished
        messages stay remembered (a few bytes each) so late polls still get COMPLETE."""
        for key in [k for k in self._partial if k[:2] == (src, session)]:
            del self._partial[key]
