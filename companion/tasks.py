"""Spawned asyncio tasks that cannot fail in silence.

A task nobody awaits until stop (a transmit queue, a keep-alive, a progress logger, a mock's
flight) that raises would otherwise die unseen: the radio goes quiet, the vehicle stops, and
the exception surfaces (if ever) at shutdown.  :func:`spawn` starts a task whose failure is
logged at once with its traceback, as a ``task_failed`` event (:mod:`companion.app.logs`, so a
JSON-lines log records it too), and handed to the owner's ``on_failure`` to act on (the link
endpoint fails its pending sends).  Cancellation is not a failure.
"""

from __future__ import annotations

import asyncio
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
        name = done.get_name()
        log.error(
            "task %s failed: %r",
            name,
            exc,
            exc_info=exc,
            extra={"event": "task_failed", "fields": {"task": name, "error": repr(exc)}},
        )
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
