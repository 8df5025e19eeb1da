"""A replay's clock that only runs while the replay's process runs.

A replay flies mock vehicles, companions and the simulated radio in one event loop at a time
scale (30x: one real second is thirty link seconds).  On :class:`~companion.radio.clock.Clock`
link time is the loop's clock times the scale, so every moment the process waits for a CPU --
a busy machine, another test beside it -- passes as thirty times as much flight and radio time
in which nobody could act: runs overrun, the fail-safe climbs, outcomes depend on the load.

:class:`PacedClock` counts only the time the loop is scheduled: a ticker wakes every
``TICK_S``, and whatever a gap between two ticks has beyond ``MAX_GAP_S`` does not pass.  A
protocol step computed inline blocks the loop, so it passes as no time either; the party
charges its measured thread CPU instead (``charges_cpu``), the same on an idle or a busy
machine.  Everything in the loop -- the vehicles' flight, the radio, the companions' timers --
reads this one clock, so they stay consistent with each other when the machine stalls.
What it cannot pace runs outside the loop: MAVSDK's server processes.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any, TypeVar

from companion.radio.clock import Clock

T = TypeVar("T")

TICK_S = 0.005  # real seconds between the ticker's wake-ups
MAX_GAP_S = 0.012  # of a longer gap between ticks only this much passes


class PacedClock(Clock):
    """Link seconds: ``scale`` times the real seconds the event loop was scheduled.

    Run :meth:`tick` as a task for as long as the clock is used; without it the clock is
    :class:`Clock`'s.  Timers (sleep, timeouts, call_later) fire once *link* time reaches
    their deadline: a real timer that comes due early, because time was held back, waits on.
    """

    def __init__(self, scale: float = 1.0) -> None:
        super().__init__(scale, charges_cpu=True)
        self._lost = 0.0  # real seconds that did not pass
        self._last: float | None = None  # the ticker's last wake-up (loop time)

    @property
    def lost_s(self) -> float:
        """Real seconds held back so far (loop stalls, inline computation)."""
        return self._lost

    def now(self) -> float:
        real = asyncio.get_running_loop().time()
        if self._last is not None:
            real = min(real, self._last + MAX_GAP_S)
        return (real - self._lost) * self.scale

    async def tick(self) -> None:
        """Observe the loop's gaps (run as a task; cancel it when done)."""
        loop = asyncio.get_running_loop()
        self._last = loop.time()
        try:
            while True:
                await asyncio.sleep(TICK_S)
                self._observe(loop.time())
        finally:
            self._last = None

    def _observe(self, real: float) -> None:
        assert self._last is not None
        gap = real - self._last
        if gap > MAX_GAP_S:
            self._lost += gap - MAX_GAP_S
        self._last = real

    def _at(self, when: float, callback: Callable[[], object]) -> _Timer:
        """Call ``callback`` once link time reaches ``when``."""
        loop = asyncio.get_running_loop()
        timer = _Timer()

        def check() -> None:
            left = when - self.now()
            if left <= 0:
                timer.handle = None
                callback()
            else:
                timer.handle = loop.call_later(left / self.scale, check)

        timer.handle = loop.call_later(max(when - self.now(), 0.0) / self.scale, check)
        return timer

    async def sleep(self, seconds: float) -> None:
        until = self.now() + max(seconds, 0.0)
        while (left := until - self.now()) > 0:
            await asyncio.sleep(left / self.scale)
        if seconds <= 0:
            await asyncio.sleep(0)

    async def wait_for(self, awaitable: Awaitable[T], seconds: float) -> T:
        async with self.timeout(seconds):
            return await awaitable

    @contextlib.asynccontextmanager
    async def timeout(self, seconds: float | None) -> AsyncIterator[None]:
        if seconds is None:
            yield
            return
        loop = asyncio.get_running_loop()
        async with asyncio.timeout(None) as cm:
            timer = self._at(self.now() + max(seconds, 0.0), lambda: cm.reschedule(loop.time()))
            try:
                yield
            finally:
                timer.cancel()

    def call_later(self, seconds: float, callback: Callable[..., object], *args: Any) -> None:
        self._at(self.now() + max(seconds, 0.0), lambda: callback(*args))


class _Timer:
    """The pending real timer of a link-time deadline (re-armed until the deadline)."""

    handle: asyncio.TimerHandle | None = None

    def cancel(self) -> None:
        if self.handle is not None:
            self.handle.cancel()
            self.handle = None
