"""The path-comparison protocol over the radio link: one asyncio task per party.

The parties are the sans-IO machines of :mod:`protocol.intersection`; this module moves their
messages through a :class:`~companion.link.LinkEndpoint`, inside the authenticated session of
:mod:`companion.auth.session` (a signed key exchange on the first two messages, AEAD on every
message).  A run ends in exactly one of two known states: the machine DONE (Alice holds her
bits), or the machine FAILED, the session closed on both sides (an ABORT frame with a one-byte
code tells the peer) and every buffer freed.  The caller gets the result or one exception: a
:class:`~protocol.errors.ProtocolError` (bad message;
:class:`~companion.auth.AuthenticationError` when it failed authentication),
:class:`~companion.link.LinkTimeout` (peer silent, retries exhausted or the run's time limit),
:class:`~companion.link.PeerAborted`, or :class:`PeerRefused` (the peer's signed refusal).

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

from protocol.errors import ProtocolError, UnknownSetupError
from protocol.intersection import Alice, Bob, State

from .auth.session import Accepted, AuthenticationError, Initiator, Refusal, Responder
from .link.arq import LinkError, LinkTimeout, PeerAborted
from .link.clock import VirtualTimeLoop
from .link.endpoint import LinkEndpoint
from .link.frames import AbortCode
from .roles import Role

T = TypeVar("T")
# Protocol steps get threads of their own: MAVSDK's blocking calls and streams occupy the
# event loop's default pool, and a step queued behind them would wait for seconds.
_WORKERS = concurrent.futures.ThreadPoolExecutor(max_workers=2, thread_name_prefix="protocol")


class PeerRefused(Exception):
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
    ) -> None:
        self.endpoint, self.peer, self.session = endpoint, peer, session
        self.machine, self.report = machine, report

    async def compute(self, step: Callable[[], T]) -> T:
        """Run one machine step.  On a clock that charges CPU (simulations) it runs inline
        and its CPU time then passes as link time; on a virtual loop it runs inline too;
        otherwise in a worker thread, so the radio (and the autopilot's MAVSDK) keep being
        served while it computes."""
        loop = asyncio.get_running_loop()
        charge = self.endpoint.clock.charges_cpu
        if charge or isinstance(loop, VirtualTimeLoop):
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

    async def send(self, data: bytes, payload: int | None = None) -> None:
        """Send ``data`` (``payload`` bytes of it the protocol's own; the rest authentication)."""
        await self.endpoint.send(self.peer, self.session, data)
        self.report.messages_sent += 1
        self.report.bytes_sent += len(data)
        self.report.auth_bytes_sent += len(data) - (len(data) if payload is None else payload)


async def _guard(party: _Party, run: Callable[[], Awaitable[None]], timeout: float | None) -> None:
    endpoint, peer, session = party.endpoint, party.peer, party.session
    try:
        async with endpoint.clock.timeout(timeout):
            await run()
    except TimeoutError:
        party.machine.abort()
        endpoint.abort(peer, session, AbortCode.TIMEOUT)
        raise LinkTimeout(f"run with node {peer} exceeded its {timeout} s limit") from None
    except AuthenticationError:
        party.machine.abort()
        endpoint.abort(peer, session, AbortCode.AUTH)
        raise
    except ProtocolError:
        party.machine.abort()
        endpoint.abort(peer, session, AbortCode.PROTOCOL)
        raise
    except (PeerAborted, PeerRefused):
        party.machine.abort()
        endpoint.close_session(peer, session)
        raise
    except LinkError:
        party.machine.abort()
        endpoint.abort(peer, session, AbortCode.LINK)
        raise
    except asyncio.CancelledError:
        party.machine.abort()
        endpoint.abort(peer, session, AbortCode.SHUTDOWN)
        raise
    else:
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
) -> RunReport:
    """Open a session to ``peer`` (Bob) and run Alice to her result.

    ``secure(session)`` makes the run's authenticated session (the link session id is part of
    what it signs); ``check_keys(boot, public_keys)`` says whether what Bob's answer carries
    (his per-start nonce and, paper suite, his public keys) is what his beacons announced."""
    session = endpoint.open(peer)
    report = RunReport(Role.ALICE, peer, session, endpoint.clock.now())
    party = _Party(endpoint, peer, session, alice, report)
    channel = secure(session) if secure is not None else None

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
            reply = await endpoint.receive(peer, session)
            if channel is not None and first:
                answer = channel.reply(reply)
                if not isinstance(answer, Accepted):
                    raise PeerRefused(answer.code)
                reply = answer.payload
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
    timeout: float | None = None,
    first: bytes | None = None,
) -> RunReport:
    """Answer the session ``peer`` opened.  Its first message waits in the inbox, or was
    taken from it already and is passed as ``first`` -- with ``secure``, the HELLO inside the
    request the :class:`Responder` verified.  A hello naming an OT setup Bob does not hold
    is answered with a signed refusal (the peer starts a fresh setup)."""
    report = RunReport(Role.BOB, peer, session, endpoint.clock.now())
    party = _Party(endpoint, peer, session, bob, report)
    pending = [first] if first is not None else []

    async def run() -> None:
        opened = False
        while bob.state is not State.DONE:
            message = pending.pop() if pending else await endpoint.receive(peer, session)
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
                await party.send(secure.accept(boot, reply), len(reply))
            else:
                await party.send(secure.seal(reply), len(reply))
            opened = True

    await _guard(party, run, timeout)
    return report
