"""An asyncio link endpoint: reliable messages over one radio, within its regulation.

Drives the pure pieces (``frames``, ``reassembly``, ``arq``, ``airtime``) with a transport and
a clock.  One radio, so one transmit queue: control frames (ACK, POLL, ABORT) go before data,
every frame waits for the duty-cycle budget (data leaves a reserve for control) and frames are
spaced by the radio's turnaround time.  Messages travel in *sessions* (peer, 16-bit id); a
session's messages are sent one at a time and arrive in order.
"""

from __future__ import annotations

import asyncio
import logging
import math
import random
import secrets
from collections.abc import Callable, Coroutine
from typing import Any

from companion.radio.airtime import DutyCycle, LinkProfile
from companion.radio.arq import (
    LinkError,
    LinkTimeout,
    MessageTooLarge,
    Outgoing,
    PeerAborted,
    PeerElsewhere,
    RetransmissionTimer,
)
from companion.radio.beacon_frames import BeaconParts, beacon_frames
from companion.radio.clock import Clock
from companion.radio.config import LinkConfig, Session
from companion.radio.frames import (
    BROADCAST,
    MAX_ACK_BITMAP,
    OVERHEAD,
    AbortCode,
    Flag,
    Frame,
    FrameError,
    FrameType,
    abort_payload,
    decode_frame,
)
from companion.radio.reassembly import Delivered, Receiver
from companion.radio.stats import ChannelUse, LinkStats
from companion.radio.transmitter import Transmitter
from companion.radio.transport import Transport
from companion.tasks import TaskScope

log = logging.getLogger("companion.radio")
CALL = b"\x00"  # several channels: a session's first message, on the common channel
ENGAGED_CYCLES = 16  # a node heard in another pair's session is engaged this long after
# (busy_ten, BUSY refusals per replay: 22 with 2 cycles, 12 with 8, 6 with 20)
USE_HORIZON_S = 30.0  # how far back the channel's use is remembered
GONE_CHECK_S = 5.0  # a receive told how to know a vanished peer looks this often
GONE_QUIET_S = 30.0  # ... and gives up once the session, too, was quiet this long
CALL_WAIT_S = 15.0  # a call not followed by a message this soon is forgotten
GRACE_RTOS = 4.0  # a session closed on its own channel is listened to this many RTOs more
FIRST_POLLS = 4  # several channels: a first message unanswered after this many probes fails
# (PeerElsewhere) -- its peer is in a run on another channel, and may be for a minute
_JITTER = random.SystemRandom()  # os.urandom-backed, like every random choice here


class LinkEndpoint:
    """Node ``node`` on a radio ``transport`` under ``profile``."""

    def __init__(
        self,
        node: int,
        transport: Transport,
        profile: LinkProfile,
        config: LinkConfig | None = None,
        clock: Clock | None = None,
    ) -> None:
        if not 0 <= node < BROADCAST:
            raise ValueError(f"node id {node} outside 0..{BROADCAST - 1}")
        self.node = node
        self.transport = transport
        self.profile = profile
        self.config = config or LinkConfig()
        self.clock = clock or Clock()
        self.frame_size = profile.max_frame
        self.payload_size = self.frame_size - OVERHEAD
        if self.payload_size < 16:
            raise ValueError(f"profile {profile.name} leaves no room for payload")
        self.idle_timeout = self.config.idle_timeout(profile)
        # a frame, its ACK and two turnarounds: what the retransmission timer waits at least
        self.cycle_s = (
            profile.airtime(self.frame_size)
            + profile.airtime(OVERHEAD + 2 + MAX_ACK_BITMAP)
            + 2 * (profile.turnaround_s + self.config.latency_allowance_s)
        )
        self.channels = self.config.channels
        if not 1 <= self.channels <= profile.channels:
            raise ValueError(
                f"{self.channels} channels: {profile.name} offers 1..{profile.channels}"
            )
        self.stats = LinkStats()
        self.receiver = Receiver(
            node,
            max_message=self.config.max_message,
            max_partial=self.config.max_partial,
            idle_timeout=self.idle_timeout,
        )
        self.duty = DutyCycle(profile.budget_s, profile.duty_window_s, self.config.control_reserve)
        self.beacons: asyncio.Queue[tuple[int, bytes]] = asyncio.Queue(maxsize=64)
        self.radio = Transmitter(transport, profile, self.duty, self.stats, self.clock)
        self.radio.listen = self._listening
        self.channel_use = ChannelUse(USE_HORIZON_S)  # frames heard and sent, any kind
        self.radio.on_air = self.channel_use.add
        self._active: tuple[int, int] | None = None  # the session the radio listens for
        self._grace = (0, -math.inf)  # (channel, until): a session just closed there
        self._closed_on: dict[tuple[int, int], int] = {}  # closed sessions' own channels
        self._sessions: dict[tuple[int, int], Session] = {}
        self._closed: dict[tuple[int, int], float] = {}
        self._aborted: dict[tuple[int, int], Frame] = {}
        self._accept: asyncio.Queue[tuple[int, int] | LinkError] = asyncio.Queue()
        self._outgoing: dict[tuple[int, int, int], tuple[Outgoing, asyncio.Event]] = {}
        self._timers: dict[int, RetransmissionTimer] = {}
        self._tasks = TaskScope(f"link-{node}", log)  # the transmitter, upkeep, lingering runs
        self._last_traffic = -math.inf
        self._others_at = -math.inf  # another pair's session frame was last heard then
        self._engaged: dict[int, float] = {}  # node -> when it was last heard in another
        # pair's session (the frame headers' src and dst are in the clear)
        self._beacon_seq = secrets.randbelow(256)
        self._beacon_parts = BeaconParts(self.stats)

    # ------------------------------------------------------------------ lifecycle

    async def start(self) -> None:
        self.radio.running = True
        self.transport.set_receiver(self._on_bytes)
        await self._tasks.open()
        self._tasks.spawn(self.radio.run(), "tx", on_failure=self._failed)
        self._tasks.spawn(self._housekeeping(), "gc", on_failure=self._failed)

    def _failed(self, name: str, exc: BaseException) -> None:
        """A link task died (logged by its :class:`~companion.tasks.TaskScope`): the radio
        is gone, so every send, receive and accept fails now with a LinkError instead of
        hanging."""
        error = LinkError(f"node {self.node}: the link failed: {exc!r}")
        self.radio.stop(error)
        for _, acked in self._outgoing.values():
            acked.set()  # its sender wakes, sees the error
        for sess in self._sessions.values():
            sess.inbox.put_nowait(error)
        self._accept.put_nowait(error)

    async def close(self) -> None:
        self.radio.running = False
        await self._tasks.close()  # (a task that died was logged)
        self.radio.fail_pending(LinkError("link endpoint closed"))
        await self.transport.close()

    async def __aenter__(self) -> LinkEndpoint:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # ------------------------------------------------------------------ sessions

    def open(self, peer: int, session: int | None = None) -> int:
        """Start a session with ``peer``; returns its id (random unless given)."""
        while session is None or (peer, session) in self._sessions:
            session = secrets.randbelow(0xFFFF) + 1
        self._closed.pop((peer, session), None)
        self._aborted.pop((peer, session), None)
        sess = self._sessions[(peer, session)] = Session(peer, session, self.clock.now())
        sess.channel = self._channel_of(peer)
        sess.ours = True
        self.receiver.trust(peer, session)  # ours: its replies are kept before anybody's
        self._listen_for(sess)  # we are about to talk in it
        return session

    async def accept(self, timeout: float | None = None) -> tuple[int, int]:
        """Wait for a peer to start a session; its first message is ready to ``receive``."""
        async with self.clock.timeout(timeout):
            item = await self._accept.get()
        if isinstance(item, LinkError):
            self._accept.put_nowait(item)  # for every other waiter too
            raise item
        return item

    def arrived_at(self, peer: int, session: int) -> float:
        """When (link time) the first fragment of a session the peer opened reached us."""
        return self._session(peer, session).arrived

    def arrived(self, peer: int, session: int) -> float:
        """:meth:`arrived_at` in Unix seconds (:meth:`Clock.wall`): what a request's own time
        is checked against (its transfer may take long)."""
        return self.clock.wall() - (self.clock.now() - self.arrived_at(peer, session))

    def close_session(self, peer: int, session: int) -> None:
        """Forget a session: its buffers are freed, late frames are ignored."""
        sess = self._sessions.pop((peer, session), None)
        self._closed[(peer, session)] = self.clock.now()
        own = sess.channel if sess is not None and sess.moved else 0
        if own:
            self._closed_on[(peer, session)] = own
        self.receiver.forget_session(peer, session)
        self.receiver.untrust(peer, session)
        if self._active == (peer, session):
            self._active = None
            if own and sess is not None and sess.accepted:
                # its peer may not have our last ACK: listen there a little longer (and
                # answer its polls), as TCP's TIME-WAIT does
                grace = GRACE_RTOS * self._timer(peer).rto
                self._grace = (own, self.clock.now() + grace)
                self.clock.call_later(grace + 1e-3, self.radio.retune)
            self.radio.retune()

    def secure(self, peer: int, session: int, check: Callable[[int, bytes], bool]) -> None:
        """The session is authenticated above the link: from now on an ABORT ends it only
        with a proof ``check(code, proof)`` accepts -- one without is anybody's, ignored
        (``unproven_abort``) -- and its partial messages are kept before anybody's."""
        self._session(peer, session).abort_check = check
        self.receiver.trust(peer, session)

    def abort(self, peer: int, session: int, code: AbortCode, proof: bytes = b"") -> None:
        """Tell the peer the session is over (three copies, and again whenever it asks for an
        ACK in this session) and close it here; ``proof``: that it is us (keyed sessions)."""
        frame = Frame(FrameType.ABORT, self.node, peer, session, payload=abort_payload(code, proof))
        channel = self._reply_channel((peer, session))
        for _ in range(3 if self.radio.running else 0):
            self._enqueue(frame, control=True, channel=channel)
        self.close_session(peer, session)
        self._aborted[(peer, session)] = frame  # repeated to whoever still asks (like a RST)

    def linger(self, peer: int, session: int, work: Coroutine[Any, Any, None]) -> None:
        """Let ``work`` keep the open session (it closes it) beside whatever comes next: a
        finished run that may still be asked for its last message.  A lingering session
        does not make the radio :meth:`busy`; it ends with the endpoint."""
        if not self._tasks.running:  # closed: nobody is left to ask
            work.close()
            self.close_session(peer, session)
            return
        self._session(peer, session).lingering = True
        if self._active == (peer, session):
            self._active = None
            self.radio.retune()
        self._tasks.spawn(work, f"linger-{peer}-{session}")

    @property
    def open_sessions(self) -> int:
        """Sessions open now (ours and those peers opened)."""
        return len(self._sessions)

    def retransmission_floor(self, peer: int) -> float:
        """The shortest time the link waits for ``peer``'s ACK before it sends again."""
        return self._timer(peer).floor

    def has_message(self, peer: int, session: int) -> bool:
        """A message of the session waits to be received."""
        sess = self._sessions.get((peer, session))
        return sess is not None and not sess.inbox.empty()

    def busy(self, quiet_s: float = 2.0) -> bool:
        """A session is open, a message half received, or session traffic was heard in the
        last ``quiet_s`` seconds: a beacon now would likely collide with somebody's run."""
        return bool(
            any(not sess.lingering for sess in self._sessions.values())
            or self.receiver.pending()
            or self.clock.now() - self._last_traffic < quiet_s
        )

    def engaged(self, node: int) -> bool:
        """``node`` was heard in another pair's session lately (within
        :data:`ENGAGED_CYCLES` frame-ACK cycles, about 8 s on SF7: a run leaves gaps between
        its messages -- a drone that sent its request waits for the reply): a request now
        would likely be refused BUSY or go unheard.  From public frame headers, which a
        stranger can forge: callers bound how long they defer to it."""
        return self.clock.now() - self._engaged.get(node, -math.inf) < ENGAGED_CYCLES * self.cycle_s

    def load(self, window_s: float) -> float:
        """Share of the last ``window_s`` the channel carried frames we heard or sent (any
        kind; :class:`~companion.radio.stats.ChannelUse`)."""
        return self.channel_use.share(self.clock.now(), window_s)

    def others_quiet_s(self) -> float:
        """Seconds since a frame of another pair's session was heard (on our channel)."""
        return self.clock.now() - self._others_at

    def budget_wait(self) -> float:
        """Seconds the next queued frame must still wait for the duty-cycle budget (0: none
        waits, or nothing is queued)."""
        return self.radio.budget_wait()

    def _session(self, peer: int, session: int) -> Session:
        try:
            return self._sessions[(peer, session)]
        except KeyError:
            raise LinkError(f"no open session {session} with node {peer}") from None

    # ------------------------------------------------------------------ messages

    async def send(self, peer: int, session: int, data: bytes) -> None:
        """Deliver ``data`` reliably to ``peer`` (returns once it acknowledged all of it).
        Several channels: a session we opened first *calls* the peer on the common channel
        (a one-byte message, :data:`CALL`) and sends everything else on its own channel."""
        sess = self._session(peer, session)
        if len(data) > self.config.max_message:
            raise MessageTooLarge(f"{len(data)} bytes > max_message {self.config.max_message}")
        if not self._settled(sess) and sess.ours and data != CALL:
            await self.send(peer, session, CALL)
        async with sess.send_lock:
            self._listen_for(sess)  # (an answer that waited for the radio takes it now)
            seq, sess.next_seq = sess.next_seq, (sess.next_seq + 1) & 0xFF
            out = Outgoing(
                self.node,
                peer,
                session,
                seq,
                data,
                self.payload_size,
                window=self.config.window,
                max_tries=self.config.max_tries,
                max_polls=self.config.max_polls if self._settled(sess) else FIRST_POLLS,
            )
            acked = asyncio.Event()
            self._outgoing[(peer, session, seq)] = (out, acked)
            try:
                while not out.complete:
                    self._raise_if_aborted(sess)
                    acked.clear()
                    frames = out.burst()
                    fresh = out.tries[frames[-1].index] == 1
                    channel = self._data_channel(sess)
                    done = [
                        self._enqueue(f, control=False, channel=channel, lead=i == 0)
                        for i, f in enumerate(frames)
                    ]
                    sent_at = await done[-1]
                    await self._await_ack(out, acked, sess, sent_at, sample=fresh)
            except LinkTimeout as exc:
                if self._settled(sess) or isinstance(exc, PeerElsewhere):
                    raise
                raise PeerElsewhere(f"node {peer}: no answer on the common channel") from exc
            finally:
                del self._outgoing[(peer, session, seq)]
                self.stats.frames_retransmitted += out.retransmissions
            sess.last_heard = self.clock.now()
            self._move(sess)  # (its first message is through)
            self.stats.messages_sent += 1
            log.debug(
                "node %d -> %d session %d: message %d of %d B acknowledged (%d fragments, "
                "%d retransmitted)",
                self.node,
                peer,
                session,
                seq,
                len(data),
                len(out.fragments),
                out.retransmissions,
            )

    async def _await_ack(
        self, out: Outgoing, acked: asyncio.Event, sess: Session, sent_at: float, sample: bool
    ) -> None:
        timer = self._timer(sess.peer)
        while True:
            # Jitter: two nodes that both wait for an ACK must not probe in lockstep, or their
            # probes collide forever.  (A first message on several channels probes without
            # backing off: a peer that does not answer is elsewhere, not overloaded.)
            rto = timer.rto if self._settled(sess) else 2 * timer.floor
            wait = rto * (1.0 + _JITTER.random() / 2)
            try:
                await self.clock.wait_for(acked.wait(), wait)
            except TimeoutError:
                self._raise_if_aborted(sess)
                if self.clock.now() - sess.last_heard < rto:
                    continue  # the peer is on the air in this session: it cannot hear a poll
                if self._settled(sess):
                    timer.timed_out()
                acked.clear()
                probe = out.probe()
                channel = self._probe_channel(sess)
                sent_at = await self._enqueue(probe, control=True, channel=channel)
                sample = False
                self.stats.polls_sent += probe.type is FrameType.POLL
                continue
            self._raise_if_aborted(sess)
            timer.answered()
            if sample:
                timer.sample(self.clock.now() - sent_at)
            return

    async def receive(
        self,
        peer: int,
        session: int,
        idle_timeout: float | None = None,
        gone: Callable[[], bool] | None = None,
    ) -> bytes:
        """The session's next message; LinkTimeout after ``idle_timeout`` of silence, or as
        soon as ``gone()`` says the peer is no longer heard (its beacons) and the session has
        been quiet for :data:`GONE_QUIET_S` (looked at every :data:`GONE_CHECK_S`): a drone
        that flew out of range or landed does not hold a run for the whole idle timeout (5
        minutes on US915; a city's hour had 94 runs still waiting when their drone landed)."""
        sess = self._session(peer, session)
        limit = self.idle_timeout if idle_timeout is None else idle_timeout
        while True:
            if sess.inbox.empty():
                self._raise_if_aborted(sess)
                quiet = self.clock.now() - sess.last_heard
                if gone is not None and quiet >= GONE_QUIET_S and gone():
                    raise LinkTimeout(f"node {peer} is no longer heard")
            remaining = sess.last_heard + limit - self.clock.now()
            if remaining <= 0 and sess.inbox.empty():
                raise LinkTimeout(f"nothing from node {peer} for {limit:.0f} s")
            wait = max(remaining, 0.0) if gone is None else min(max(remaining, 0.0), GONE_CHECK_S)
            try:
                item = await self.clock.wait_for(sess.inbox.get(), wait)
            except TimeoutError:
                continue
            if isinstance(item, LinkError):  # the peer aborted, or the link failed
                raise item
            self.stats.messages_received += 1
            log.debug(
                "node %d <- %d session %d: message of %d B", self.node, peer, session, len(item)
            )
            return item

    async def beacon(self, payload: bytes) -> None:
        """Broadcast one beacon (unacknowledged; it spends the data budget, not the reserve
        kept for acknowledgements): one frame, or a few fragments where the profile's frames
        are small (US915 SF9), which a receiver puts together or drops whole."""
        seq, self._beacon_seq = self._beacon_seq, (self._beacon_seq + 1) & 0xFF
        frames = beacon_frames(self.node, seq, payload, self.payload_size)
        done = [self._enqueue(frame, control=False, beacon=True) for frame in frames]
        for sent in done:
            await sent

    def _raise_if_aborted(self, sess: Session) -> None:
        if self.radio.error is not None:
            raise self.radio.error
        if sess.aborted is not None:
            raise sess.aborted
        if (sess.peer, sess.session) not in self._sessions:
            raise LinkError(f"session {sess.session} with node {sess.peer} was closed")

    def _timer(self, peer: int) -> RetransmissionTimer:
        timer = self._timers.get(peer)
        if timer is None:
            p = self.profile
            # The peer may still be sending one frame, then turns around and acknowledges.
            model = self.cycle_s
            # A peer that spent its duty-cycle budget may stay silent for up to a window: the
            # backoff must let 20 probes outlast that.  Elsewhere silence means trouble.
            limit = p.duty_window_s / 8 if p.duty_cycle else 30 * model
            timer = self._timers[peer] = RetransmissionTimer(model, limit)
        return timer

    # ------------------------------------------------------------------ radio

    def _enqueue(
        self,
        frame: Frame,
        *,
        control: bool,
        channel: int = 0,
        beacon: bool = False,
        lead: bool = False,
    ) -> asyncio.Future[float]:
        return self.radio.enqueue(
            frame.encode(), control=control, channel=channel, beacon=beacon, lead=lead
        )

    # ------------------------------------------------------------------ channels

    def _channel_of(self, responder: int) -> int:
        """A session's own channel: 1..channels-1 from the node that answers it (both ends
        find the same one; its sessions take turns on its one radio anyway, and sessions
        with other responders are most likely elsewhere), 0 with one channel."""
        if self.channels == 1:
            return 0
        return 1 + responder % (self.channels - 1)

    def _move(self, sess: Session) -> None:
        """The session's first message is through: the rest of it is on its own channel,
        and the radio listens there -- unless it is busy with another session of ours."""
        if not sess.moved:
            sess.moved = True
            active = self._sessions.get(self._active) if self._active else None
            if active is None or active.lingering or active is sess:
                self._listen_for(sess)

    def _listen_for(self, sess: Session) -> None:
        self._active = (sess.peer, sess.session)
        self.radio.retune()

    def _settled(self, sess: Session) -> bool:
        """One channel, or the session's first message is through."""
        return self.channels == 1 or sess.moved

    def _data_channel(self, sess: Session) -> int:
        return sess.channel if sess.moved else 0

    def _probe_channel(self, sess: Session) -> int:
        """Where to ask for an ACK: the session's channel once moved; before, its first
        message's ACK may have been lost after the peer moved on, so every other probe goes
        to the session's channel (and the radio listens where the probe went)."""
        if self._settled(sess):
            return self._data_channel(sess)
        sess.probes += 1
        sess.listen_on = sess.channel if sess.probes % 2 == 0 else 0
        self._listen_for(sess)
        return sess.listen_on

    def _reply_channel(self, key: tuple[int, int]) -> int:
        """Where our ACKs and ABORTs of a session go: its channel once it moved, else the
        common one (a first message is answered where it came)."""
        sess = self._sessions.get(key)
        if sess is None:  # a session just closed answers where it was (its peer may still be)
            return self._closed_on.get(key, 0)
        return self._data_channel(sess)

    def _listening(self) -> int:
        """Where the radio listens between frames: the active session's channel (or, before
        it moved, where its last probe went), else any open session's that moved, else the
        common channel."""
        sess = self._sessions.get(self._active) if self._active else None
        if sess is not None and not sess.lingering:
            return sess.hears_on()
        for other in self._sessions.values():
            if not other.lingering and (other.moved or other.ours):
                return other.hears_on()
        channel, until = self._grace
        return channel if self.clock.now() < until else 0

    async def _housekeeping(self) -> None:
        while True:
            await self.clock.sleep(max(self.idle_timeout / 4, 1.0))
            now = self.clock.now()
            for peer, session in self._sessions:
                self.receiver.touch(peer, session, now)  # open: keep what it delivered
            self.receiver.expire(now)
            for key in [k for k, t in self._closed.items() if now - t > self.idle_timeout]:
                del self._closed[key]
                self._aborted.pop(key, None)
                self._closed_on.pop(key, None)
            for node in [n for n, t in self._engaged.items() if now - t > self.idle_timeout]:
                del self._engaged[node]

    def _on_bytes(self, data: bytes) -> None:
        self.channel_use.add(self.clock.now(), self.profile.airtime(len(data)))
        try:
            frame = decode_frame(data)
        except FrameError as exc:
            self.stats.drop(exc.reason)
            return
        now = self.clock.now()
        if frame.type is not FrameType.BEACON:
            self._last_traffic = now  # a run on the air, ours or another pair's
        if frame.dst not in (self.node, BROADCAST):
            self._engaged[frame.src] = self._engaged[frame.dst] = now
            self._others_at = now
            return  # overheard: another pair's traffic
        self.stats.frames_received += 1
        self.stats.bytes_received += len(data)
        key = (frame.src, frame.session)
        sess = self._sessions.get(key)
        if sess is not None:
            sess.last_heard = now
        # Any frame of the session (an ACK of our message too) shows the peer is still in it:
        # the receiver must go on recognising copies of what it already delivered.
        self.receiver.touch(frame.src, frame.session, now)
        if frame.type in (FrameType.DATA, FrameType.POLL) and key in self._aborted:
            if frame.type is FrameType.POLL or frame.flags & Flag.ACK_REQ:
                self._enqueue(self._aborted[key], control=True, channel=self._reply_channel(key))
        elif frame.type in (FrameType.DATA, FrameType.POLL):
            delivered, ack = self.receiver.on_frame(frame, now)
            if ack is not None:
                self._enqueue(ack, control=True, channel=self._reply_channel(key))
                self.stats.acks_sent += 1
            if delivered is not None:
                self._deliver(delivered, now)
        elif frame.type is FrameType.ACK:
            entry = self._outgoing.get((frame.src, frame.session, frame.seq))
            if entry is not None and entry[0].on_ack(frame):
                entry[1].set()
        elif frame.type is FrameType.ABORT:
            check = None if sess is None else sess.abort_check
            if check is not None and not check(frame.payload[0], frame.payload[1:]):
                self.stats.drop("unproven_abort")  # anybody's: the run goes on
                return
            if sess is not None and sess.aborted is None:
                sess.aborted = PeerAborted(AbortCode(frame.payload[0]))
                sess.inbox.put_nowait(sess.aborted)
                for (peer, session, _), (_, event) in self._outgoing.items():
                    if (peer, session) == key:
                        event.set()
            self.receiver.forget_session(*key)
        elif frame.type is FrameType.BEACON:
            payload = self._beacon_parts.add(frame, now)
            if payload is not None:
                if self.beacons.full():
                    self.beacons.get_nowait()
                self.beacons.put_nowait((frame.src, payload))

    def _deliver(self, message: Delivered, now: float) -> None:
        key = (message.src, message.session)
        if key in self._closed:
            self.stats.drop("closed_session")
            return
        sess = self._sessions.get(key)
        if sess is None:
            if len(self._sessions) >= self.config.max_sessions:
                self.stats.drop("too_many_sessions")
                return
            sess = self._sessions[key] = Session(
                message.src, message.session, now, arrived=message.started
            )
            sess.channel = self._channel_of(self.node)
            self._move(sess)  # (its first message is through)
            if self.channels > 1 and message.data == CALL:
                # a call: the session's messages follow on its channel, or it is forgotten
                sess.accepted = False
                self.clock.call_later(CALL_WAIT_S, self._call_expired, key)
                return
            self._accept.put_nowait(key)
        elif not sess.accepted:
            sess.accepted = True
            self._accept.put_nowait(key)
        sess.inbox.put_nowait(message.data)

    def _call_expired(self, key: tuple[int, int]) -> None:
        """A call not followed by a message (lost, or anybody's): back to the common
        channel."""
        sess = self._sessions.get(key)
        if sess is not None and not sess.accepted and not self.receiver.pending_from(*key):
            self.stats.drop("unanswered_call")
            self.close_session(*key)
