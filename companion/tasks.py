"""Spawned asyncio tasks that cannot fail in silence.

A task nobody awaits until stop (a transmit queue, a keep-alive, a progress logger, a mock's
flight) that raises would otherwise die unseen: the radio goes quiet, the vehicle stops, and
the exception surfaces (if ever) at shutdown.  :func:`spawn` starts a task whose failure is
logged at once with its traceback, as a ``task_failed`` event (:mod:`companion.logs`, so a
JSON-lines log records it too), and handed to the owner's ``on_failure`` to act on (the link
endpoint fails its pending sends).  Cancellation is not a failure.

Work that lives and dies with an object (a companion's loops and runs, a link endpoint's
transmitter and lingering sessions) runs in a :class:`TaskScope`: one
:class:`asyncio.TaskGroup`, opened with the object and cancelled as a whole when it closes;
a task that fails is logged and reported the same way and ends nothing else in the group.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

T = TypeVar("T")
FailureHook = Callable[[BaseException], None]


def watch(
    task: asyncio.Task[T], log: logging.Logger, on_failure: FailureHook | None = None
) -> asyncio.Task[T]:
    """``task`` with a done-callback that logs and reports its failure (returns it)."""

    def ended(done: asyncio.Task[T]) -> None:
        if done.cancelled():
            return
        exc = done.exception()  # retrieved: no "exception was never retrieved" at exit
        if exc is None:
            return
        _log_failure(log, done.get_name(), exc)
        if on_failure is not None:
            on_failure(exc)

    task.add_done_callback(ended)
    return task


def spawn(
    work: Coroutine[Any, Any, T],
    *,
    name: str,
    log: logging.Logger,
    on_failure: FailureHook | None = None,
) -> asyncio.Task[T]:
    """``asyncio.create_task(work, name=name)``, :func:`watch`\\ ed."""
    return watch(asyncio.create_task(work, name=name), log, on_failure)


def _log_failure(log: logging.Logger, name: str, exc: BaseException) -> None:
    log.error(
        "task %s failed: %r",
        name,
        exc,
        exc_info=exc,
        extra={"event": "task_failed", "fields": {"task": name, "error": repr(exc)}},
    )


class TaskScope:
    """Tasks that live and die together (see the module): :meth:`open` the group,
    :meth:`spawn` into it, :meth:`close` cancels and awaits all of it (bounded by
    ``grace_s`` real seconds: a close never hangs on a task that will not end).  A task's
    failure is logged and handed to its ``on_failure`` (or the scope's) with its name."""

    def __init__(
        self,
        name: str,
        log: logging.Logger,
        on_failure: Callable[[str, BaseException], None] | None = None,
        grace_s: float = 10.0,
    ) -> None:
        self.name = name
        self._log = log
        self._on_failure = on_failure
        self._grace_s = grace_s
        self._group: asyncio.TaskGroup | None = None
        self._main: asyncio.Task[None] | None = None

    @property
    def running(self) -> bool:
        """Opened and not closed: the group is up."""
        return self._main is not None and not self._main.done()

    async def open(self) -> None:
        """Start the group (returns once it takes tasks)."""
        if self.running:
            return
        ready = asyncio.Event()
        self._main = asyncio.create_task(self._hold(ready), name=self.name)
        await ready.wait()

    async def _hold(self, ready: asyncio.Event) -> None:
        try:
            async with asyncio.TaskGroup() as group:
                self._group = group
                ready.set()
                await asyncio.Future()  # until close() cancels us
        finally:
            self._group = None

    def spawn(
        self,
        work: Coroutine[Any, Any, None],
        name: str,
        on_failure: Callable[[str, BaseException], None] | None = None,
    ) -> asyncio.Task[None]:
        """``work`` as a task of the group, named ``<scope>-<name>``."""
        if self._group is None:
            work.close()
            raise RuntimeError(f"{self.name}: not open")
        hook = on_failure if on_failure is not None else self._on_failure
        task = f"{self.name}-{name}"
        made = self._group.create_task(self._guarded(work, name, task, hook), name=task)
        # a task cancelled before it ran (the scope closing) never started ``work``: close
        # it, or Python warns that it was never awaited (a no-op for work that ran)
        made.add_done_callback(lambda _: work.close())
        return made

    async def _guarded(
        self,
        work: Coroutine[Any, Any, None],
        name: str,
        task: str,
        hook: Callable[[str, BaseException], None] | None,
    ) -> None:
        try:
            await work
        except Exception as exc:  # logged and reported; the group and its other tasks go on
            _log_failure(self._log, task, exc)
            if hook is not None:
                hook(name, exc)

    async def close(self) -> None:
        """Cancel every task of the group and wait for them (bounded)."""
        main, self._main = self._main, None
        if main is None:
            return
        main.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            try:
                await asyncio.wait_for(asyncio.shield(main), self._grace_s)
            except TimeoutError:
                self._log.warning("%s: tasks did not stop", self.name)
