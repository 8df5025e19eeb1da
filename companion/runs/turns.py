"""Turns on the radio: one run on the air at a time, the most urgent first.

A drone has one half-duplex radio.  Two runs at once (as Alice with one peer, as Bob for
another) would only make each other's frames collide and time out, so runs take turns.  A
waiting run goes by priority (lower first), then by arrival: answering a peer's near run,
answering a full run, our own near runs, our own full runs.  Answers go first: the drone
that asked waits with its own radio idle, and other drones may wait on it -- a chain of
drones each waiting for the next is as slow as all its runs together.  For the same reason
a request is refused ``BUSY`` at once (:meth:`companion.runs.bob.BobAnswers._admit`)
rather than kept waiting when our own run on the air still waits for its peer's first reply
(that peer may be busy itself), or when another answer already waits: a waiting request
waits for one run under way at most.
"""

from __future__ import annotations

import asyncio
import heapq
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from protocol.intersection import Alice

ANSWER_NEAR, ANSWER_FULL, OWN_NEAR, OWN_FULL = 0, 1, 2, 3


class RadioTurns:
    def __init__(self) -> None:
        self._taken = False
        self._waiting: list[tuple[int, int, asyncio.Future[None]]] = []
        self._arrivals = 0

    @property
    def taken(self) -> bool:
        return self._taken

    def waiting(self) -> int:
        return sum(not f.done() for _, _, f in self._waiting)

    @asynccontextmanager
    async def turn(self, priority: int) -> AsyncIterator[None]:
        if self._taken:
            future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
            heapq.heappush(self._waiting, (priority, self._arrivals, future))
            self._arrivals += 1
            try:
                await future
            except asyncio.CancelledError:
                if future.done() and not future.cancelled():
                    self._release()  # the turn came with the cancellation: pass it on
                raise
        else:
            self._taken = True
        try:
            yield
        finally:
            self._release()

    def _release(self) -> None:
        """Hand the radio to the best waiter still waiting, or free it."""
        while self._waiting:
            _, _, future = heapq.heappop(self._waiting)
            if not future.done():
                future.set_result(None)
                return
        self._taken = False


class Air:
    """What a companion has on its one radio: the turns, the runs on the air (as Alice or
    Bob), our own run's machine while it holds the radio, and the admitted answers waiting
    for it."""

    def __init__(self) -> None:
        self.turns = RadioTurns()
        self.sessions = 0  # runs on the air
        self.own: Alice | None = None  # our own run's machine while it holds the radio
        self.answers_waiting = 0  # admitted answers waiting for the radio (at most one)

    @property
    def in_run(self) -> bool:
        """A run is on the air, as Alice or as Bob."""
        return self.sessions > 0

    def too_busy_to_wait(self) -> bool:
        """Our own run holds the radio and still waits for its peer's first reply (a third
        drone, perhaps busy itself), or another answer already waits for the radio: a request
        kept waiting would keep its sender's radio idle too, a chain of drones each waiting
        on the next (see the module).  Otherwise it waits: at most one answer behind a run
        that is under way."""
        return (self.own is not None and self.own.n is None) or self.answers_waiting > 0
