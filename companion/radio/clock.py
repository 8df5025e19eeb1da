"""Link time.

All link code reads time through :class:`Clock` in *link seconds*.  With ``scale`` > 1 the
link runs that many times faster than the event loop's clock (replays at a time scale); on a
:class:`companion.sim.virtual_time.VirtualTimeLoop` the loop's clock is virtual.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

T = TypeVar("T")


class Clock:
    """Seconds of link time; ``scale`` link seconds pass per second of the event loop.

    ``charges_cpu``: a simulation's clock on which each protocol step is computed inline and
    its thread CPU then passes as link time (the run's own computer, modelled; see
    :mod:`companion.runs.exchange`) -- not a drone's, whose steps run in a worker thread."""

    def __init__(self, scale: float = 1.0, *, charges_cpu: bool = False) -> None:
        if scale <= 0:
            raise ValueError("time scale must be positive")
        self.scale = scale
        self.charges_cpu = charges_cpu
        self._wall_offset: float | None = None

    def now(self) -> float:
        return asyncio.get_running_loop().time() * self.scale

    def virtual(self) -> bool:
        """Whether the running loop's time is virtual (it jumps instead of sleeping: work in
        a worker thread would let it run ahead)."""
        return bool(getattr(asyncio.get_running_loop(), "virtual_time", False))

    def wall(self) -> float:
        """Unix seconds in link time: the wall clock (GPS time on a drone) when first asked,
        advanced by link seconds since -- one time base for every party sharing this clock,
        also in a replay at a time scale or on a virtual clock (beacon and request times)."""
        if self._wall_offset is None:
            self._wall_offset = time.time() - self.now()
        return self._wall_offset + self.now()

    def shift_wall(self, seconds: float) -> None:
        """The wall clock jumps by ``seconds`` while link time goes on (a GPS fix after a
        drift; hours passing in a simulation)."""
        self._wall_offset = self.wall() - self.now() + seconds

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(seconds, 0.0) / self.scale)

    async def wait_for(self, awaitable: Awaitable[T], seconds: float) -> T:
        """Like :func:`asyncio.wait_for`, in link seconds (raises TimeoutError)."""
        return await asyncio.wait_for(awaitable, max(seconds, 0.0) / self.scale)

    def timeout(self, seconds: float | None) -> contextlib.AbstractAsyncContextManager[object]:
        return asyncio.timeout(None if seconds is None else seconds / self.scale)

    def call_later(self, seconds: float, callback: Callable[..., object], *args: Any) -> None:
        asyncio.get_running_loop().call_later(max(seconds, 0.0) / self.scale, callback, *args)
