"""Link time, and an event loop whose clock is virtual.

All link code reads time through :class:`Clock` in *link seconds*.  With ``scale`` > 1 the
link runs that many times faster than the event loop's clock (replays at a time scale).
:class:`VirtualTimeLoop` is an asyncio loop that never sleeps: whenever every task waits on a
timer it jumps straight to the next one, so an hour of duty-cycle waiting costs microseconds.
It is for simulations without real I/O; a simulation in which everything waits forever raises
:class:`SimulationStalled` instead of hanging.
"""

from __future__ import annotations

import asyncio
import contextlib
import selectors
import time
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


class Clock:
    """Seconds of link time; ``scale`` link seconds pass per second of the event loop.

    ``charges_cpu``: a simulation's clock on which each protocol step is computed inline and
    its thread CPU then passes as link time (the run's own computer, modelled; see
    :mod:`companion.exchange`) -- not a drone's, whose steps run in a worker thread."""

    def __init__(self, scale: float = 1.0, *, charges_cpu: bool = False) -> None:
        if scale <= 0:
            raise ValueError("time scale must be positive")
        self.scale = scale
        self.charges_cpu = charges_cpu
        self._wall_offset: float | None = None

    def now(self) -> float:
        return asyncio.get_running_loop().time() * self.scale

    def wall(self) -> float:
        """Unix seconds in link time: the wall clock (GPS time on a drone) when first asked,
        advanced by link seconds since -- one time base for every party sharing this clock,
        also in a replay at a time scale or on a virtual clock (beacon and request times)."""
        if self._wall_offset is None:
            self._wall_offset = time.time() - self.now()
        return self._wall_offset + self.now()

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(seconds, 0.0) / self.scale)

    async def wait_for(self, awaitable: Awaitable[T], seconds: float) -> T:
        """Like :func:`asyncio.wait_for`, in link seconds (raises TimeoutError)."""
        return await asyncio.wait_for(awaitable, max(seconds, 0.0) / self.scale)

    def timeout(self, seconds: float | None) -> contextlib.AbstractAsyncContextManager[object]:
        return asyncio.timeout(None if seconds is None else seconds / self.scale)

    def call_later(self, seconds: float, callback: Callable[..., object], *args: Any) -> None:
        asyncio.get_running_loop().call_later(max(seconds, 0.0) / self.scale, callback, *args)


class SimulationStalled(RuntimeError):
    """Every task of a virtual-time simulation waits and no timer is pending."""


class _VirtualSelector(selectors.BaseSelector):
    """Polls the real selector without blocking; turns a blocking wait into a time jump."""

    def __init__(self, loop: VirtualTimeLoop) -> None:
        self._real = selectors.DefaultSelector()
        self._loop = loop

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._real.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._real.modify(fileobj, events, data)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        events = self._real.select(0)
        if events or timeout == 0:
            return events
        if timeout is None:
            raise SimulationStalled("every task waits and no timer is pending")
        self._loop.advance(timeout)
        return []

    def close(self) -> None:
        self._real.close()

    def get_map(self) -> Any:
        return self._real.get_map()


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An event loop whose ``time()`` starts at 0 and advances only by jumps."""

    def __init__(self) -> None:
        self._virtual_now = 0.0
        super().__init__(_VirtualSelector(self))

    def time(self) -> float:
        return self._virtual_now

    def advance(self, seconds: float) -> None:
        self._virtual_now += seconds


def run_simulated(main: Coroutine[Any, Any, T]) -> T:
    """Run a coroutine on a fresh virtual-time loop."""
    with asyncio.Runner(loop_factory=VirtualTimeLoop) as runner:
        return runner.run(main)
