"""One radio's transmit queue, within its regulation.

Control frames (ACK, POLL, ABORT) go first, then beacons, then data: a beacon queued behind a
run's burst of 64 frames went out 20 s late on SF7, and in a busy sky peers went unheard for
a minute -- the fail-safe then assumes they flew straight at us all that time (busy_ten: every
precaution of the first minute).  Every frame waits for the duty-cycle budget
(:class:`~companion.radio.airtime.DutyCycle`, data leaving a reserve for control), listens
before talking where the transport can sense the channel (LoRa channel activity detection;
a beacon or control frame looks again sooner than data, and a burst starts only once the
channel has stayed idle for :data:`LEAD_IDLE_S`, so other drones' beacons get between a
run's messages), and frames are spaced by the radio's turnaround time.  The endpoint
(:class:`~companion.radio.endpoint.LinkEndpoint`) enqueues encoded frames and awaits the time
each one left.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from companion.radio.airtime import DutyCycle, LinkProfile
from companion.radio.arq import LinkError
from companion.radio.clock import Clock
from companion.radio.stats import LinkStats
from companion.radio.transport import Transport

_JITTER = random.SystemRandom()  # os.urandom-backed, like every random choice here

MAX_DEFER_S = 8.0  # listen before talk gives up waiting after this long (or three of the
# profile's longest frames, if longer: at SF12 one frame is 8 s on the air)
LEAD_IDLE_S = 0.1  # a burst's first data frame waits for the channel to stay idle this long
DATA_BACKOFF_S = (0.02, 0.25)  # a data frame that found the channel busy looks again after
PRIORITY_BACKOFF_S = (0.005, 0.03)  # ... a beacon or control frame sooner


def _consume(future: asyncio.Future[float]) -> None:
    future.exception()  # marks the exception retrieved


@dataclass
class _TxItem:
    data: bytes
    airtime: float
    control: bool
    done: asyncio.Future[float]
    channel: int = 0
    lead: bool = False  # the first data frame of a burst
    idle_at: float | None = None  # (lead) since when the channel is idle, as far as known


class Transmitter:
    """The queue in front of ``transport``; :meth:`run` is the endpoint's transmit task."""

    def __init__(
        self,
        transport: Transport,
        profile: LinkProfile,
        duty: DutyCycle,
        stats: LinkStats,
        clock: Clock,
    ) -> None:
        self.transport, self.profile, self.duty = transport, profile, duty
        self.stats, self.clock = stats, clock
        self.running = False
        self.error: LinkError | None = None  # why it stopped for good (its task died)
        self._control: deque[_TxItem] = deque()
        self._beacons: deque[_TxItem] = deque()  # data frames that go before a run's
        self._data: deque[_TxItem] = deque()
        self._wake = asyncio.Event()
        # where the radio listens between frames (several channels: the endpoint's choice)
        self.listen: Callable[[], int] = lambda: 0
        # told of each frame once it is on the air: (ended at, seconds on the air)
        self.on_air: Callable[[float, float], None] = lambda end, air: None
        self._tune: Callable[[int], None] | None = getattr(transport, "tune", None)
        self._sending = False

    def retune(self) -> None:
        """Listen where :attr:`listen` says now (after the frame on the air, if one is)."""
        if self._tune is not None and not self._sending:
            self._tune(self.listen())

    def enqueue(
        self,
        data: bytes,
        *,
        control: bool,
        channel: int = 0,
        beacon: bool = False,
        lead: bool = False,
    ) -> asyncio.Future[float]:
        """Queue one encoded frame (to go on ``channel`` of the region; ``beacon``: ahead of
        other data, spending the data budget; ``lead``: a data frame that starts a burst);
        the future gives the link time it finished leaving."""
        if not self.running:
            raise self.error or LinkError("link endpoint is not running")
        done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
        item = _TxItem(data, self.profile.airtime(len(data)), control, done, channel, lead)
        (self._control if control else self._beacons if beacon else self._data).append(item)
        self._wake.set()
        return done

    def _queue(self) -> deque[_TxItem]:
        """The queue whose head goes next."""
        return self._control or self._beacons or self._data

    def budget_wait(self) -> float:
        """Seconds the frame at the head of the queue must wait for the duty-cycle budget."""
        queue = self._queue()
        if not queue:
            return 0.0
        now = self.clock.now()
        item = queue[0]
        return max(self.duty.earliest(now, item.airtime, control=item.control) - now, 0.0)

    def fail_pending(self, error: LinkError) -> None:
        """The endpoint closes: a sender waiting on a queued frame gets ``error``."""
        for item in (*self._control, *self._beacons, *self._data):
            if not item.done.done():  # a sender waiting on it gets the error, nobody else
                item.done.set_exception(error)
                item.done.add_done_callback(_consume)
        self._control.clear()
        self._beacons.clear()
        self._data.clear()

    def stop(self, error: LinkError) -> None:
        """The radio is gone for good (its task died): every queued and later frame fails
        with ``error``."""
        self.running = False
        self.error = error
        self.fail_pending(error)

    async def run(self) -> None:
        deferred_since: float | None = None
        patience = max(MAX_DEFER_S, 3 * self.profile.airtime(self.profile.max_frame))
        while True:
            queue = self._queue()
            if not queue:
                self._wake.clear()
                await self._wake.wait()
                continue
            item = queue[0]
            now = self.clock.now()
            start = self.duty.earliest(now, item.airtime, control=item.control)
            if start > now:
                self._wake.clear()
                with contextlib.suppress(TimeoutError):
                    await self.clock.wait_for(self._wake.wait(), start - now)
                self.stats.duty_wait_s += self.clock.now() - now
                continue  # re-evaluate: a control frame may have arrived
            sense = getattr(self.transport, "channel_busy", None)
            if self._tune is not None:
                self._tune(item.channel)  # (listen before talk on the frame's channel)
            if deferred_since is None:
                deferred_since = now
            if sense is not None and now - deferred_since < patience:
                if sense():
                    # Listen before talk: another radio is on the air (LoRa channel
                    # activity detection).  Back off and look again -- a beacon or control
                    # frame sooner than data, so it takes the next gap.
                    item.idle_at = None
                    low, high = DATA_BACKOFF_S if queue is self._data else PRIORITY_BACKOFF_S
                    await self.clock.sleep(_JITTER.uniform(low, high))
                    continue
                if item.lead and (item.idle_at is None or now - item.idle_at > 2 * LEAD_IDLE_S):
                    # A new burst starts only on a channel idle for a moment: the frames of
                    # a run follow each other 10 ms apart, and without such gaps other
                    # drones' beacons found the channel busy for seconds (busy_ten: 8 % of
                    # beacons went out only after 8 s of waiting, into somebody's frame).
                    item.idle_at = now
                    await self.clock.sleep(LEAD_IDLE_S)
                    continue  # (and look again: idle still, it goes; a wait that other
                    # frames of ours interrupted is done again)
            deferred_since = None
            queue.popleft()
            if item.done.cancelled():
                continue
            self.duty.record(now, item.airtime)
            self._sending = True
            try:
                await self.transport.transmit(item.data, item.airtime)
            finally:
                self._sending = False
            self.stats.frames_sent += 1
            self.stats.bytes_sent += len(item.data)
            self.stats.airtime_s += item.airtime
            self.on_air(self.clock.now(), item.airtime)
            self.retune()
            if not item.done.done():
                item.done.set_result(self.clock.now())
            await self.clock.sleep(self.profile.turnaround_s)
