"""The path-comparison protocol over the radio link: one asyncio task per party.

The parties are the sans-IO machines of :mod:`protocol.intersection`; this module only moves
their messages through a :class:`~companion.link.LinkEndpoint`.  A run ends in exactly one of
two known states: the machine DONE (Alice holds her bits), or the machine FAILED, the session
closed on both sides (an ABORT frame tells the peer why) and every buffer freed.  The caller
gets the result or one exception: a :class:`~protocol.errors.ProtocolError` (bad message),
:class:`~companion.link.LinkTimeout` (peer silent, retries exhausted or the run's time limit),
or :class:`~companion.link.PeerAborted`.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TypeVar

from protocol.errors import ProtocolError
from protocol.intersection import Alice, Bob, State

from .link.arq import LinkError, LinkTimeout, PeerAborted
from .link.clock import VirtualTimeLoop
from .link.endpoint import (
    ABORT_LINK,
    ABORT_PROTOCOL,
    ABORT_SHUTDOWN,
    ABORT_TIMEOUT,
    LinkEndpoint,
)

T = TypeVar("T")
# Protocol steps get threads of their own: MAVSDK's blocking calls and streams occupy the
# event loop's default pool, and a step queued behind them would wait for seconds.
_WORKERS = concurrent.futures.ThreadPoolExecutor(max_workers=2, thread_name_prefix="protocol")


@dataclass
class RunReport:
    """What one party saw of one run."""

    role: str
    peer: int
    session: int
    started: float
    finished: float = 0.0
    cpu_s: float = 0.0
    messages_sent: int = 0
    bytes_sent: int = 0
    hits: list[bool] = field(default_factory=list)

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
        charge_cpu: bool,
    ) -> None:
        self.endpoint, self.peer, self.session = endpoint, peer, session
        self.machine, self.report, self.charge_cpu = machine, report, charge_cpu

    async def compute(self, step: Callable[[], T]) -> T:
        """Run one machine step.  On a virtual clock it runs inline and its CPU time passes as
        link time; in real time it runs in a worker thread, so the radio (and the autopilot's
        MAVSDK) keep being served while it computes."""
        loop = asyncio.get_running_loop()
        if self.charge_cpu or isinstance(loop, VirtualTimeLoop):
            # Virtual time must not run ahead of a worker thread: compute inline.
            start = time.process_time()
            result = step()
            spent = time.process_time() - start
            self.report.cpu_s += spent
            if self.charge_cpu:
                await self.endpoint.clock.sleep(spent)
            return result

        def timed() -> tuple[T, float]:
            start = time.thread_time()
            out = step()
            return out, time.thread_time() - start

        result, spent = await loop.run_in_executor(_WORKERS, timed)
        self.report.cpu_s += spent
        return result

    async def send(self, data: bytes) -> None:
        await self.endpoint.send(self.peer, self.session, data)
        self.report.messages_sent += 1
        self.report.bytes_sent += len(data)


async def _guard(party: _Party, run: Callable[[], Awaitable[None]], timeout: float | None) -> None:
    endpoint, peer, session = party.endpoint, party.peer, party.session
    try:
        async with endpoint.clock.timeout(timeout):
            await run()
    except TimeoutError:
        party.machine.abort()
        endpoint.abort(peer, session, ABORT_TIMEOUT, "run time limit")
        raise LinkTimeout(f"run with node {peer} exceeded its {timeout} s limit") from None
    except ProtocolError as exc:
        party.machine.abort()
        endpoint.abort(peer, session, ABORT_PROTOCOL, str(exc))
        raise
    except PeerAborted:
        party.machine.abort()
        endpoint.close_session(peer, session)
        raise
    except LinkError as exc:
        party.machine.abort()
        endpoint.abort(peer, session, ABORT_LINK, str(exc))
        raise
    except asyncio.CancelledError:
        party.machine.abort()
        endpoint.abort(peer, session, ABORT_SHUTDOWN, "cancelled")
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
    timeout: float | None = None,
    charge_cpu: bool = False,
) -> RunReport:
    """Open a session to ``peer`` (Bob) and run Alice to her result."""
    session = endpoint.open(peer)
    report = RunReport("alice", peer, session, endpoint.clock.now())
    party = _Party(endpoint, peer, session, alice, report, charge_cpu)

    async def run() -> None:
        message: bytes | None = await party.compute(alice.start)
        while message is not None:
            await party.send(message)
            reply = await endpoint.receive(peer, session)
            message = await party.compute(partial(alice.receive, reply))

    await _guard(party, run, timeout)
    report.hits = alice.hits
    return report


async def serve_bob(
    endpoint: LinkEndpoint,
    peer: int,
    session: int,
    bob: Bob,
    *,
    timeout: float | None = None,
    charge_cpu: bool = False,
    first: bytes | None = None,
) -> RunReport:
    """Answer the session ``peer`` opened (its first message waits in the inbox, or was
    taken from it already and is passed as ``first``)."""
    report = RunReport("bob", peer, session, endpoint.clock.now())
    party = _Party(endpoint, peer, session, bob, report, charge_cpu)
    pending = [first] if first is not None else []

    async def run() -> None:
        while bob.state is not State.DONE:
            message = pending.pop() if pending else await endpoint.receive(peer, session)
            reply = await party.compute(partial(bob.receive, message))
            if reply is not None:
                await party.send(reply)

    await _guard(party, run, timeout)
    return report
