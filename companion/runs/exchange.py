"""The path-comparison protocol over the radio link: one asyncio task per party.

The parties are the sans-IO machines of :mod:`protocol.intersection`; this module moves their
messages through a :class:`~companion.radio.LinkEndpoint`, inside the authenticated session of
:mod:`companion.auth.session` (a signed key exchange on the first two messages, AEAD on every
message).  A run ends in exactly one of two known states: the machine DONE (Alice holds her
bits), or the machine FAILED, the session closed on both sides (an ABORT frame with a one-byte
code and its proof tells the peer) and every buffer freed.  The caller gets the result or one
exception: a :class:`~protocol.errors.ProtocolError` (bad message;
:class:`~companion.auth.AuthenticationError` when it failed authentication),
:class:`~companion.radio.LinkTimeout` (peer silent, retries exhausted or the run's time limit),
:class:`~companion.radio.PeerAborted`, or :class:`PeerRefused` (the peer's signed refusal).

Nobody else can end or spend a run: the link ignores an abort without the session's proof
(:meth:`~companion.radio.LinkEndpoint.secure`: the peer's signature, and once the keys exist
its MAC).  Once keyed, while ``alive()`` says the peer is still heard, a message the link
gave up on (a jammer) is sent again until the peer has it, and silence is waited out, within
the run's time limit -- Bob counts a run from his first reply on, and what he computed
reaches Alice unless every copy is jammed for that long.  An acknowledgement is anybody's to
forge, so a keyed run that hears nothing for a while sends its own last message again, and
Bob keeps a finished run's session open for a few such silences (beside his radio turn) to
answer a copy of Alice's last message with his last one.  A copy received again is no news
and is skipped.

Without a session object (``secure=None``) the messages travel in the clear: benchmarks use it
to measure what authentication adds; the companion never does.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TypeVar

from companion.auth.session import Accepted, AuthenticationError, Initiator, Refusal, Responder
from companion.errors import CompanionError
from companion.mission.ground import COVER_ALL
from companion.radio.arq import LinkError, LinkTimeout, PeerAborted, PeerElsewhere
from companion.radio.endpoint import LinkEndpoint
from companion.radio.frames import AbortCode
from companion.roles import Role
from protocol.errors import ProtocolError, UnknownSetupError
from protocol.intersection import Alice, Bob
from protocol.run import State

T = TypeVar("T")
# Protocol steps get threads of their own: MAVSDK's blocking calls and streams occupy the
# event loop's default pool, and a step queued behind them would wait for seconds.
_WORKERS = concurrent.futures.ThreadPoolExecutor(max_workers=2, thread_name_prefix="protocol")
RESEND_PAUSE_S = 5.0  # before a sealed message the link gave up on goes again
QUIET_S = 120.0  # a keyed run's silence (at least) before our last message goes again
LINGER_QUIETS = 4  # Bob keeps a finished run's session this many silences long


class PeerRefused(CompanionError):
    """The peer declined the run, with a signed reason."""

    def __init__(self, code: Refusal) -> None:
        super().__init__(f"peer refused the run: {code.name.lower()}")
        self.code = code


@dataclass
class RunReport:
    """What one party saw of one run.  ``bytes_sent`` counts what went to the link;
    ``auth_bytes_sent`` the part of it authentication added (key exchange, tags)."""

    role: Role
    peer: int
    session: int
    started: float
    finished: float = 0.0
    cpu_s: float = 0.0
    messages_sent: int = 0
    bytes_sent: int = 0
    auth_bytes_sent: int = 0
    hits: list[bool] = field(default_factory=list)
    refused: Refusal | None = None  # Bob: the run ended with this signed refusal of his
    resent: int = 0  # sealed messages sent again after the link gave up on them (a jammer)
    cover: int = COVER_ALL  # Alice: how much of her horizon Bob's answer covers, in eighths

    @property
    def wall_s(self) -> float:
        return self.finished - self.started


class _Party:
    def __init__(
        self,
        endpoint: LinkEndpoint,
        peer: int,
        session: int,
        machine: Alice | Bob,
        report: RunReport,
        channel: Initiator | Responder | None = None,
        alive: Callable[[], bool] | None = None,
    ) -> None:
        self.endpoint, self.peer, self.session = endpoint, peer, session
        self.machine, self.report = machine, report
        self.channel, self.alive = channel, alive
        self.last_received = b""
        self.last_sent = b""  # once keyed: sent again when the peer stays silent

    async def compute(self, step: Callable[[], T]) -> T:
        """Run one machine step.  On a clock that charges CPU (simulations) it runs inline
        and its CPU time then passes as link time; on a virtual loop it runs inline too;
        otherwise in a worker thread, so the radio (and the autopilot's MAVSDK) keep being
        served while it computes."""
        loop = asyncio.get_running_loop()
        charge = self.endpoint.clock.charges_cpu
        if charge or self.endpoint.clock.virtual():
            # Virtual time must not run ahead of a worker thread: compute inline.
            start = time.thread_time()  # this thread's CPU: not MAVSDK's threads beside it
            result = step()
            spent = time.thread_time() - start
            self.report.cpu_s += spent
            if charge:
                await self.endpoint.clock.sleep(spent)
            return result

        def timed() -> tuple[T, float]:
            start = time.thread_time()
            out = step()
            return out, time.thread_time() - start

        result, spent = await loop.run_in_executor(_WORKERS, timed)
        self.report.cpu_s += spent
        return result

    def _persists(self) -> bool:
        """Whether to go on trying when the link gives up: the session is keyed (Bob counts
        the run from his first reply on) and the peer is still heard -- a jammer, not a
        drone gone.  The run's time limit (``_guard``) bounds it."""
        keyed = self.channel is not None and self.channel.keyed
        return keyed and self.alive is not None and self.alive()

    async def send(self, data: bytes, payload: int | None = None, *, copy: bool = False) -> None:
        """Send ``data`` (``payload`` bytes of it the protocol's own; the rest authentication;
        ``copy``: our last message again, not counted).  A sealed message the link gave up on
        goes again (a new copy) while :meth:`_persists`, unless the peer's next message shows
        it arrived."""
        while True:
            try:
                await self.endpoint.send(self.peer, self.session, data)
                break
            except LinkTimeout:
                if not self._persists():
                    raise
                if self.endpoint.has_message(self.peer, self.session):
                    break  # the peer answered it: it arrived, only the ACKs were lost
                self.report.resent += 1
                await self.endpoint.clock.sleep(RESEND_PAUSE_S)
        if self.channel is not None and self.channel.keyed:
            self.last_sent = data
        if copy:  # a copy sent again: the link's statistics count it
            return
        self.report.messages_sent += 1
        self.report.bytes_sent += len(data)
        self.report.auth_bytes_sent += len(data) - (len(data) if payload is None else payload)

    async def receive(self) -> bytes:
        """The peer's next message; a copy of the last one (sent again: our acknowledgement
        was lost) is skipped.  Once keyed, while the peer is heard, a silence of
        :meth:`_quiet_s` makes our own last message go again: the peer may wait for it
        while we wait for its answer (a copy the link took for delivered on an
        acknowledgement anybody can forge).  A peer no longer heard at all (``alive()``
        false: no beacon, no frame) ends the run at once; otherwise the link's idle timeout
        counts from the last frame of the session."""
        while True:
            persists = self._persists()
            try:
                message = await self.endpoint.receive(
                    self.peer, self.session, self._quiet_s() if persists else None, gone=self._gone
                )
            except LinkTimeout:
                if not persists:
                    raise
                if self.last_sent:
                    self.report.resent += 1
                    await self.send(self.last_sent, copy=True)
                else:
                    await self.endpoint.clock.sleep(RESEND_PAUSE_S)
                continue
            if message != self.last_received:
                self.last_received = message
                return message

    def _gone(self) -> bool:
        """The peer is no longer heard at all (``alive`` given and false) -- on a link
        without a duty cycle: under one, a peer that spent its budget is silent, beacons
        too, for up to a window (lossy_sf9's runs failed over and over), and the idle
        timeout allows for that."""
        if self.endpoint.profile.duty_cycle:
            return False
        return self.alive is not None and not self.alive()

    def _quiet_s(self) -> float:
        """How long a keyed run waits in silence before it sends its last message again (a
        duty cycle may hold a frame back for a tenth of the idle timeout)."""
        return max(QUIET_S, self.endpoint.idle_timeout / 10)

    def abort(self, code: AbortCode) -> None:
        """End the run here and tell the peer, with the session's proof once it is keyed."""
        self.machine.abort()
        proof = b"" if self.channel is None else self.channel.abort_proof(code)
        self.endpoint.abort(self.peer, self.session, code, proof)


async def _guard(
    party: _Party, run: Callable[[], Awaitable[None]], timeout: float | None, *, close: bool = True
) -> None:
    """Run ``run`` within ``timeout``; whatever ends it, the machine and the session end in a
    known state (``close=False``: a run that ended well leaves the session open, for
    :func:`_linger`)."""
    endpoint, peer, session = party.endpoint, party.peer, party.session
    try:
        async with endpoint.clock.timeout(timeout):
            await run()
    except TimeoutError:
        party.abort(AbortCode.TIMEOUT)
        raise LinkTimeout(f"run with node {peer} exceeded its {timeout} s limit") from None
    except AuthenticationError:
        party.abort(AbortCode.AUTH)
        raise
    except ProtocolError:
        party.abort(AbortCode.PROTOCOL)
        raise
    except (PeerAborted, PeerRefused, PeerElsewhere):  # (elsewhere: it would not hear an ABORT)
        party.machine.abort()
        endpoint.close_session(peer, session)
        raise
    except LinkError:
        party.abort(AbortCode.LINK)
        raise
    except asyncio.CancelledError:
        party.abort(AbortCode.SHUTDOWN)
        raise
    else:
        if close:
            endpoint.close_session(peer, session)
    finally:
        party.report.finished = endpoint.clock.now()


async def run_alice(
    endpoint: LinkEndpoint,
    peer: int,
    alice: Alice,
    *,
    secure: Callable[[int], Initiator] | None = None,
    check_keys: Callable[[bytes, bytes], bool] | None = None,
    timeout: float | None = None,
    alive: Callable[[], bool] | None = None,
) -> RunReport:
    """Open a session to ``peer`` (Bob) and run Alice to her result.

    ``secure(session)`` makes the run's authenticated session (the link session id is part of
    what it signs); ``check_keys(boot, public_keys)`` says whether what Bob's answer carries
    (his per-start nonce and, paper suite, his public keys) is what his beacons announced.
    ``alive()``: whether Bob is still heard (a message the link gave up on goes again).
    With a session, only Bob's proven abort (or signed refusal) ends the run."""
    session = endpoint.open(peer)
    report = RunReport(Role.ALICE, peer, session, endpoint.clock.now())
    channel = secure(session) if secure is not None else None
    party = _Party(endpoint, peer, session, alice, report, channel, alive)
    if channel is not None:
        endpoint.secure(peer, session, channel.abort_checks)

    async def run() -> None:
        message: bytes | None = await party.compute(alice.start)
        first = True
        while message is not None:
            if channel is None:
                await party.send(message)
            elif first:
                await party.send(channel.first(message), len(message))
            else:
                await party.send(channel.seal(message), len(message))
            reply = await party.receive()
            if channel is not None and first:
                answer = channel.reply(reply)
                if not isinstance(answer, Accepted):
                    raise PeerRefused(answer.code)
                reply = answer.payload
                if answer.cover > COVER_ALL:
                    raise AuthenticationError(f"cover {answer.cover} out of range")
                report.cover = answer.cover
                message = await party.compute(partial(alice.receive, reply))
                if check_keys is not None and not check_keys(answer.boot, alice.peer_keys):
                    raise AuthenticationError("the peer's keys do not match its beacons")
            else:
                if channel is not None:
                    reply = channel.open(reply)
                message = await party.compute(partial(alice.receive, reply))
            first = False

    await _guard(party, run, timeout)
    report.hits = alice.hits
    return report


async def serve_bob(
    endpoint: LinkEndpoint,
    peer: int,
    session: int,
    bob: Bob,
    *,
    secure: Responder | None = None,
    boot: bytes = b"",
    cover: Callable[[], int] | None = None,
    timeout: float | None = None,
    first: bytes | None = None,
    alive: Callable[[], bool] | None = None,
) -> RunReport:
    """Answer the session ``peer`` opened.  Its first message waits in the inbox, or was
    taken from it already and is passed as ``first`` -- with ``secure``, the HELLO inside the
    request the :class:`Responder` verified.  ``cover()``, asked once the first reply is
    computed, goes back sealed with it (:attr:`RunReport.cover`; all of it without).  A
    hello naming an OT setup Bob does not hold is answered with a signed refusal (the peer
    starts a fresh setup)."""
    report = RunReport(Role.BOB, peer, session, endpoint.clock.now())
    party = _Party(endpoint, peer, session, bob, report, secure, alive)
    pending = [first] if first is not None else []
    if secure is not None:
        endpoint.secure(peer, session, secure.abort_checks)  # verified: only Alice ends it

    async def run() -> None:
        opened = False
        while bob.state is not State.DONE:
            message = pending.pop() if pending else await party.receive()
            if secure is not None and opened:
                message = secure.open(message)
            try:
                reply = await party.compute(partial(bob.receive, message))
            except UnknownSetupError:
                if secure is None or opened:
                    raise
                await party.send(secure.refuse(Refusal.UNKNOWN_SETUP), 0)
                report.refused = Refusal.UNKNOWN_SETUP
                return
            if reply is None:
                continue
            if secure is None:
                await party.send(reply)
            elif not opened:
                covered = COVER_ALL if cover is None else cover()
                await party.send(secure.accept(boot, reply, cover=covered), len(reply))
            else:
                await party.send(secure.seal(reply), len(reply))
            opened = True

    keyed = secure is not None and secure.keyed and alive is not None
    await _guard(party, run, timeout, close=not keyed)
    if keyed:
        endpoint.linger(peer, session, _linger(party))
    return report


async def _linger(party: _Party) -> None:
    """Bob after his last message, beside the radio turn: for ``LINGER_QUIETS`` of Alice's
    silences, a copy of her last message -- she is still waiting: an acknowledgement
    anybody can forge, or a jammed fragment, took ours for delivered -- is answered with
    our last message again.  Then the session closes."""
    endpoint, peer, session = party.endpoint, party.peer, party.session
    seconds = LINGER_QUIETS * party._quiet_s()
    try:
        async with endpoint.clock.timeout(seconds):
            while True:
                message = await endpoint.receive(peer, session, seconds)
                if message == party.last_received and party.last_sent:
                    party.report.resent += 1
                    await endpoint.send(peer, session, party.last_sent)
    except (TimeoutError, LinkError):
        pass
    finally:
        endpoint.close_session(peer, session)
