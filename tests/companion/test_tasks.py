"""Tasks that cannot fail in silence, and task scopes that end as a whole
(companion.tasks)."""

from __future__ import annotations

import asyncio
import inspect
import logging

import pytest

from companion.tasks import TaskScope, spawn


def test_a_failed_task_in_a_scope_is_reported_and_ends_nothing_else(
    caplog: pytest.LogCaptureFixture,
) -> None:
    failures: list[tuple[str, str]] = []

    async def main() -> tuple[bool, bool, bool, bool]:
        scope = TaskScope(
            "probe", logging.getLogger("probe"), lambda n, e: failures.append((n, repr(e)))
        )
        await scope.open()

        async def broken() -> None:
            raise RuntimeError("boom")

        steady = scope.spawn(asyncio.sleep(3600), "steady")
        own: list[tuple[str, BaseException]] = []
        scope.spawn(broken(), "broken")
        scope.spawn(broken(), "other", on_failure=lambda n, e: own.append((n, e)))
        await asyncio.sleep(0.01)
        alive = scope.running and not steady.done()
        await scope.close()
        return alive, steady.cancelled(), scope.running, len(own) == 1

    with caplog.at_level(logging.ERROR, logger="probe"):
        alive, cancelled, running, own_hook = asyncio.run(main())
    assert alive and cancelled and not running and own_hook
    assert failures == [("broken", "RuntimeError('boom')")]  # the scope's hook, once
    logged = [r for r in caplog.records if getattr(r, "event", None) == "task_failed"]
    assert {r.fields["task"] for r in logged} == {"probe-broken", "probe-other"}  # type: ignore[attr-defined]


def test_a_scope_takes_no_task_before_it_opens_and_closes_within_its_grace() -> None:
    async def main() -> float:
        scope = TaskScope("probe", logging.getLogger("probe"), grace_s=0.2)
        work = asyncio.sleep(1)
        with pytest.raises(RuntimeError, match="not open"):
            scope.spawn(work, "early")

        async def stubborn() -> None:
            try:
                await asyncio.sleep(3600)
            except asyncio.CancelledError:
                await asyncio.sleep(5)  # takes its time to end (cancelled again at exit)

        await scope.open()
        scope.spawn(stubborn(), "stubborn")
        await asyncio.sleep(0)
        loop = asyncio.get_running_loop()
        began = loop.time()
        await scope.close()  # bounded: it does not hang on the stubborn task
        return loop.time() - began

    assert asyncio.run(main()) < 1.0


def test_a_lone_task_that_fails_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    seen: list[BaseException] = []

    async def main() -> None:
        async def broken() -> None:
            raise ValueError("bad")

        task = spawn(broken(), name="lone", log=logging.getLogger("probe"), on_failure=seen.append)
        await asyncio.sleep(0.01)
        assert task.done()

    with caplog.at_level(logging.ERROR, logger="probe"):
        asyncio.run(main())
    assert len(seen) == 1 and any("lone" in r.getMessage() for r in caplog.records)


def test_work_whose_task_never_ran_is_closed_not_left_unawaited() -> None:
    """A task cancelled before its first turn (its scope closing) never starts its work:
    the work is closed, not left for Python to warn "coroutine ... was never awaited" (seen
    in a CI run)."""

    async def work() -> None:
        await asyncio.sleep(3600)

    async def main() -> tuple[bool, str]:
        scope = TaskScope("closing", logging.getLogger("closing"))
        await scope.open()
        late = work()
        task = scope.spawn(late, "late")
        task.cancel()  # before it had a turn
        await asyncio.sleep(0.01)
        state = inspect.getcoroutinestate(late)
        await scope.close()
        return task.cancelled(), state

    cancelled, state = asyncio.run(main())
    assert cancelled and state == inspect.CORO_CLOSED
