"""An event loop whose clock is virtual (simulations only).

:class:`VirtualTimeLoop` is an asyncio loop that never sleeps: whenever every task waits on a
timer it jumps straight to the next one, so an hour of duty-cycle waiting costs microseconds.
It is for simulations without real I/O; a simulation in which everything waits forever raises
:class:`SimulationStalled` instead of hanging.
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Coroutine
from typing import Any, TypeVar

from companion.errors import CompanionError

T = TypeVar("T")


class SimulationStalled(CompanionError):
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

    virtual_time = True  # read by :meth:`companion.radio.clock.Clock.virtual`

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
