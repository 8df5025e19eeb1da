"""Sending side of the link: selective-repeat ARQ for one message (pure).

The message is cut into fragments of ``payload_size`` bytes.  The sender transmits a *burst*:
every unacknowledged fragment within ``window`` of the lowest one, the last flagged ACK_REQ.
The receiver answers with one ACK that covers the whole burst (cumulative point + bitmap), and
the next burst carries only what is still missing.  If no ACK comes within the retransmission
timeout the sender sends a small POLL instead of repeating data (or, with a single fragment
outstanding, that fragment).  A fragment goes out in at most ``max_tries`` bursts and at most
``max_polls`` probes in a row go unanswered; beyond either bound the message fails with
:class:`LinkTimeout`.  The receiver's state is named by an *epoch* in its ACKs; a new epoch
(it dropped a partial message) makes the sender start over rather than trust old ACKs.
"""

from __future__ import annotations

from companion.errors import CompanionError
from companion.radio.frames import AbortCode, AckInfo, Flag, Frame, FrameType


class LinkError(CompanionError):
    """Base class of the link's errors."""


class LinkTimeout(LinkError):
    """The peer did not answer within the retry bounds or the run's time limit."""


class PeerElsewhere(LinkTimeout):
    """No answer to a session's first message on a link with several channels: the peer is
    most likely in a run on another channel (what a BUSY refusal says on one channel)."""


class PeerAborted(LinkError):
    """The peer ended the session (ABORT frame: end the run, nothing more; on a secured
    session only with its proof, :meth:`LinkEndpoint.secure`)."""

    def __init__(self, code: AbortCode) -> None:
        super().__init__(f"peer aborted the session: {code.name.lower()} (code {code})")
        self.code = code


class MessageTooLarge(LinkError):
    """The message exceeds the configured maximum or 65535 fragments."""


class Outgoing:
    """State of one message being sent to ``dst``."""

    def __init__(
        self,
        src: int,
        dst: int,
        session: int,
        seq: int,
        data: bytes,
        payload_size: int,
        *,
        window: int = 64,
        max_tries: int = 24,
        max_polls: int = 20,
    ) -> None:
        if payload_size < 1:
            raise ValueError("payload size must be positive")
        count = max(1, -(-len(data) // payload_size))
        if count > 0xFFFF:
            raise MessageTooLarge(f"{len(data)} bytes need {count} > 65535 fragments")
        self.src, self.dst, self.session, self.seq = src, dst, session, seq
        self.fragments = [data[i * payload_size : (i + 1) * payload_size] for i in range(count)]
        self.window = min(window, 8 * 32 + 1)
        self.max_tries = max_tries
        self.max_polls = max_polls
        self.acked = [False] * count
        self.tries = [0] * count
        self.unanswered_polls = 0
        self.complete = False
        self.epoch: int | None = None
        self.restarts = 0

    @property
    def count(self) -> int:
        return len(self.fragments)

    @property
    def retransmissions(self) -> int:
        return sum(max(t - 1, 0) for t in self.tries)

    def burst(self) -> list[Frame]:
        """The next burst of DATA frames (empty when everything is acknowledged)."""
        if self.complete:
            return []
        first = self.acked.index(False)
        todo = [i for i in range(first, min(first + self.window, self.count)) if not self.acked[i]]
        frames = []
        for position, i in enumerate(todo):
            if self.tries[i] >= self.max_tries:
                raise LinkTimeout(
                    f"fragment {i}/{self.count} of message {self.seq} to node {self.dst} "
                    f"unacknowledged after {self.max_tries} transmissions"
                )
            self.tries[i] += 1
            last = position == len(todo) - 1
            frames.append(self._data(i, Flag.ACK_REQ if last else Flag.NONE))
        return frames

    def probe(self) -> Frame:
        """What to send after a timeout; raises once ``max_polls`` probes went unanswered.

        With one fragment outstanding the probe is that fragment again (if it was lost, this
        saves a round; if the ACK was lost, the receiver acknowledges the copy), otherwise a
        small POLL asks for the receiver's bitmap.
        """
        if self.unanswered_polls >= self.max_polls:
            raise LinkTimeout(
                f"node {self.dst} silent after {self.max_polls} probes for message {self.seq}"
            )
        self.unanswered_polls += 1
        if self.acked.count(False) == 1:
            # Bounded by max_polls like a POLL: a lost ACK is not a lost fragment.
            i = self.acked.index(False)
            self.tries[i] += 1
            return self._data(i, Flag.ACK_REQ)
        return Frame(FrameType.POLL, self.src, self.dst, self.session, self.seq, 0, self.count)

    def _data(self, i: int, flags: Flag) -> Frame:
        return Frame(
            FrameType.DATA,
            self.src,
            self.dst,
            self.session,
            self.seq,
            i,
            self.count,
            self.fragments[i],
            flags,
        )

    def on_ack(self, frame: Frame) -> bool:
        """Apply an ACK frame; True if it was for this message."""
        if (frame.src, frame.session, frame.seq, frame.count) != (
            self.dst,
            self.session,
            self.seq,
            self.count,
        ):
            return False
        self.unanswered_polls = 0
        if frame.flags & Flag.COMPLETE:
            self.complete = True
            self.acked = [True] * self.count
            return True
        info = AckInfo.decode(frame.payload)
        if info.epoch == 0:
            return True  # "holding nothing": news only before anything was acknowledged
        if info.epoch != self.epoch:
            if self.epoch is not None:
                # A new copy at the receiver: it dropped what it had confirmed (a long
                # silence, a restart).  Start over from what the new copy holds.
                self.acked = [False] * self.count
                self.restarts += 1
            self.epoch = info.epoch
        for i in info.received():
            if i >= self.count:
                continue
            self.acked[i] = True
        self.complete = all(self.acked)
        return True


class RetransmissionTimer:
    """RFC 6298-style estimator seeded from the airtime model, with exponential backoff."""

    def __init__(self, model_s: float, max_s: float) -> None:
        self.floor = model_s
        self.max_s = max(max_s, model_s)
        self.srtt: float | None = None
        self.rttvar = model_s / 2
        self.backoff = 1

    @property
    def rto(self) -> float:
        base = self.floor if self.srtt is None else max(self.floor, self.srtt + 4 * self.rttvar)
        return min(base * self.backoff, self.max_s)

    def sample(self, rtt: float) -> None:
        """A measured ACK delay (Karn: only for requests that were not repeated)."""
        if self.srtt is None:
            self.srtt, self.rttvar = rtt, rtt / 2
        else:
            self.rttvar = 0.75 * self.rttvar + 0.25 * abs(self.srtt - rtt)
            self.srtt = 0.875 * self.srtt + 0.125 * rtt
        self.backoff = 1

    def answered(self) -> None:
        """The peer answered: its silence is over, so is the backoff."""
        self.backoff = 1

    def timed_out(self) -> None:
        if self.floor * self.backoff < self.max_s:
            self.backoff *= 2
