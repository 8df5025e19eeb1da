"""Receiving side of the link: reassembly, duplicate suppression, acknowledgements (pure).

Fragments are stored as they arrive (nothing is allocated from a claimed size), so a forged
``count`` costs nothing.  A message is delivered once, when its last missing fragment arrives.
Partial messages that hear nothing for ``idle_timeout`` seconds are dropped and their memory
freed.

Anybody can put a first fragment on the air, so room is kept for those who proved who they
are: the sessions the layer above *trusts* (:meth:`Receiver.trust`: ours, and a peer's once
its request authenticated).  When ``max_partial`` partial messages are held, a new one takes
the place of the untrusted partial heard from longest ago; a trusted one is never evicted
for an untrusted one.  A flood of forged first fragments then costs its sender airtime and
evicts only its own kind: a genuine message, whose fragments come in bursts, is evicted only
if ``max_partial`` forged frames fit between two of its fragments (its sender's next burst
begins it again).  Before, a full store refused every new message until ``idle_timeout``
(5 minutes on US915, 3 hours on EU868): eight forged frames made a drone deaf.  What it
remembers of delivered streams is bounded the same way (``max_streams``, untrusted first).

Delivery is at most once and in order per *stream* (source, session): a sender has one
message of a session in flight at a time and numbers them (``seq``, mod 256), so the receiver
remembers, per stream, the last message it delivered.  Later copies of that message's
fragments, and polls for it, are answered with a COMPLETE acknowledgement; anything of an
older message is stale (its sender has finished with it) and ignored.  A stream is remembered
while its session is alive -- every frame of the session, in either direction's traffic,
renews it (:meth:`Receiver.touch`) -- and ``idle_timeout`` after that, not per message: a
sender can stay silent about an unacknowledged message for longer than the idle timeout while
the session is busy with the peer's long reply, and a receiver that forgot the message then
would take its next probe for a new copy and deliver the message a second time.

Each partial copy of a message is named by an *epoch* in its ACKs, and a copy dropped and begun
again must show a new one, or its sender trusts its stale acknowledgements, takes the message
for complete and it is lost.  Epochs therefore count round (from a random start, for a
restarted receiver) instead of being drawn at random per copy, which repeated the previous
epoch once in 255 restarts.
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass, field

from companion.radio.frames import AckInfo, Flag, Frame, FrameType

Key = tuple[int, int, int]  # (source node, session, message seq)
StreamKey = tuple[int, int]  # (source node, session)
SEQ_MOD = 256  # ``seq`` is a u8 on the wire


@dataclass(frozen=True, slots=True)
class Delivered:
    src: int
    session: int
    seq: int
    data: bytes
    started: float = 0.0  # when its first fragment (of this copy) arrived


@dataclass
class _Partial:
    count: int
    last_heard: float
    epoch: int
    fragments: dict[int, bytes] = field(default_factory=dict)
    size: int = 0
    started: float = 0.0


@dataclass
class _Stream:
    """The last message delivered from one (source, session): earlier ones are finished."""

    seq: int
    count: int
    last_heard: float


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
        max_streams: int = 256,
        epoch: int | None = None,
    ) -> None:
        self.node = node
        self.max_message = max_message
        self.max_partial = max_partial
        self.max_streams = max_streams
        self.idle_timeout = idle_timeout
        self.stats = ReceiverStats()
        self._partial: dict[Key, _Partial] = {}
        self._streams: dict[StreamKey, _Stream] = {}
        self._trusted: set[StreamKey] = set()
        # Of the last partial copy begun: from a random start (a restarted receiver's first
        # epoch is the old one once in 255 restarts), or ``epoch`` where a test needs it.
        self._epoch = secrets.randbelow(255) + 1 if epoch is None else epoch

    @property
    def buffered_bytes(self) -> int:
        return sum(p.size for p in self._partial.values())

    def streams(self) -> frozenset[tuple[int, int]]:
        """The (sender, session) streams whose delivered messages it remembers."""
        return frozenset(self._streams)

    def pending(self) -> int:
        return len(self._partial)

    def pending_from(self, src: int, session: int) -> bool:
        """A message of this stream is half received."""
        return any(key[:2] == (src, session) for key in self._partial)

    def on_frame(self, frame: Frame, now: float) -> tuple[Delivered | None, Frame | None]:
        """Consume one DATA or POLL frame; return (message completed, ACK frame to send)."""
        key = (frame.src, frame.session, frame.seq)
        stream = self._streams.get(key[:2])
        if stream is not None:
            stream.last_heard = now
            age = (stream.seq - frame.seq) % SEQ_MOD
            if age < SEQ_MOD // 2:  # the last delivered message (age 0) or an older one
                if frame.type is FrameType.DATA:
                    self.stats.duplicates += 1
                if age:
                    return None, None  # stale: its sender finished it before sending the last
                if frame.count != stream.count:
                    self.stats.refuse("inconsistent")
                    return None, None
                return None, self._ack(frame, AckInfo(stream.count), Flag.COMPLETE)
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
            if len(self._partial) >= self.max_partial and not self._evict(key[:2]):
                self.stats.refuse("too_many_partial")
                return None, None
            partial = self._partial[key] = _Partial(
                frame.count, now, self._next_epoch(), started=now
            )
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
            self._remember(key[:2], _Stream(frame.seq, partial.count, now))
            for older in [k for k in self._partial if k[:2] == key[:2]]:
                del self._partial[older]  # abandoned by its sender (it moved on): stale
            self.stats.delivered += 1
            delivered = Delivered(frame.src, frame.session, frame.seq, data, partial.started)
            return delivered, self._ack(frame, AckInfo(partial.count), Flag.COMPLETE)
        if frame.flags & Flag.ACK_REQ:
            return None, self._ack(frame, self._info(partial))
        return None, None

    def trust(self, src: int, session: int) -> None:
        """The session is authenticated (or ours): keep its partial messages before others."""
        self._trusted.add((src, session))

    def untrust(self, src: int, session: int) -> None:
        self._trusted.discard((src, session))

    def _evict(self, newcomer: StreamKey) -> bool:
        """Make room for a partial message of ``newcomer``: drop the untrusted partial heard
        from longest ago (a trusted newcomer may also take an untrusted one's place, an
        untrusted one never a trusted one's).  False: none may go."""
        untrusted = [k for k in self._partial if k[:2] not in self._trusted]
        if not untrusted:
            return False
        oldest = min(untrusted, key=lambda k: self._partial[k].last_heard)
        del self._partial[oldest]
        self.stats.refuse("evicted")
        return True

    def _remember(self, stream: StreamKey, last: _Stream) -> None:
        """Remember what a stream delivered, within ``max_streams`` (the untrusted stream
        heard from longest ago goes first: forged one-frame messages cannot fill memory)."""
        self._streams[stream] = last
        while len(self._streams) > self.max_streams:
            untrusted = [k for k in self._streams if k not in self._trusted] or list(self._streams)
            del self._streams[min(untrusted, key=lambda k: self._streams[k].last_heard)]

    def _next_epoch(self) -> int:
        """Epochs go round 1..255 (0 means "holds none"), so a copy begun again differs from
        the copy before unless a multiple of 255 other copies were begun in between."""
        self._epoch = self._epoch % 255 + 1
        return self._epoch

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

    def touch(self, src: int, session: int, now: float) -> None:
        """The session with ``src`` is alive (a frame of it was heard, or it is open): keep
        remembering what it delivered."""
        stream = self._streams.get((src, session))
        if stream is not None:
            stream.last_heard = max(stream.last_heard, now)

    def expire(self, now: float) -> int:
        """Free partial messages idle for ``idle_timeout`` and forget streams whose session
        was silent that long; returns the number of partial messages freed."""
        stale = [k for k, p in self._partial.items() if now - p.last_heard >= self.idle_timeout]
        for key in stale:
            del self._partial[key]
        self.stats.expired += len(stale)
        old = [k for k, t in self._streams.items() if now - t.last_heard >= self.idle_timeout]
        for stream_key in old:
            del self._streams[stream_key]
        return len(stale)

    def forget_session(self, src: int, session: int) -> None:
        """Free the partial messages of a session that ended or was aborted.  What it
        delivered stays remembered (a few bytes) so late polls still get COMPLETE."""
        for key in [k for k in self._partial if k[:2] == (src, session)]:
            del self._partial[key]
