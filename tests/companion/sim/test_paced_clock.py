"""The replay's paced clock: link time passes only while the event loop is scheduled, and
every timer fires by link time, never early (a stall holds link time back)."""

from __future__ import annotations

import asyncio
import time

import pytest

from companion.sim.paced_clock import MAX_GAP_S, PacedClock

SCALE = 10.0


async def _ticking(clock: PacedClock) -> asyncio.Task[None]:
    ticker = asyncio.create_task(clock.tick())
    await asyncio.sleep(0.02)  # the ticker has run
    return ticker


async def _stop(ticker: asyncio.Task[None]) -> None:
    ticker.cancel()
    await asyncio.gather(ticker, return_exceptions=True)


def test_free_loop_runs_at_scale() -> None:
    async def main() -> float:
        clock = PacedClock(SCALE)
        ticker = await _ticking(clock)
        t0, r0 = clock.now(), time.monotonic()
        await asyncio.sleep(0.2)
        link, real = clock.now() - t0, time.monotonic() - r0
        await _stop(ticker)
        return link / (real * SCALE)

    assert 0.5 <= asyncio.run(main()) <= 1.02  # less only when the machine stalls it


def test_a_stall_does_not_pass() -> None:
    """A blocked loop (a busy machine, an inline computation) passes at most one gap."""

    async def main() -> tuple[float, float]:
        clock = PacedClock(SCALE)
        ticker = await _ticking(clock)
        t0 = clock.now()
        time.sleep(0.3)  # the loop cannot run
        during = clock.now() - t0
        await asyncio.sleep(0.01)  # the ticker sees the gap
        after = clock.now() - t0
        await _stop(ticker)
        return during, after

    during, after = asyncio.run(main())
    assert during <= (MAX_GAP_S + 0.001) * SCALE
    assert after <= (MAX_GAP_S + 0.05) * SCALE  # and the time held back stays held back
    assert after >= during  # monotone across the ticker's correction


def test_timers_wait_for_link_time_across_a_stall() -> None:
    """sleep, wait_for, timeout and call_later: none fires before its link deadline."""

    async def main() -> dict[str, float]:
        clock = PacedClock(SCALE)
        ticker = await _ticking(clock)
        t0 = clock.now()
        fired: dict[str, float] = {}

        async def stall() -> None:
            await asyncio.sleep(0.02)
            time.sleep(0.15)  # 1.5 link seconds that must not pass

        async def sleeper() -> None:
            await clock.sleep(2.0)
            fired["sleep"] = clock.now() - t0

        async def waiter() -> None:
            with pytest.raises(TimeoutError):
                await clock.wait_for(asyncio.Event().wait(), 2.0)
            fired["wait_for"] = clock.now() - t0

        async def timed() -> None:
            with pytest.raises(TimeoutError):
                async with clock.timeout(2.0):
                    await asyncio.sleep(10)
            fired["timeout"] = clock.now() - t0

        clock.call_later(2.0, lambda: fired.setdefault("call_later", clock.now() - t0))
        await asyncio.gather(stall(), sleeper(), waiter(), timed())
        await clock.sleep(0.5)
        await _stop(ticker)
        return fired

    fired = asyncio.run(main())
    assert set(fired) == {"sleep", "wait_for", "timeout", "call_later"}
    for name, at in fired.items():
        assert 2.0 <= at < 2.0 + 0.5, name  # on time in link seconds, not 1.5 s early


def test_timeout_none_and_results_pass_through() -> None:
    async def main() -> int:
        clock = PacedClock(SCALE)
        ticker = await _ticking(clock)
        async with clock.timeout(None):
            await clock.sleep(0)
        value = await clock.wait_for(asyncio.sleep(0.01, result=7), 5.0)
        await _stop(ticker)
        return value

    assert asyncio.run(main()) == 7


def test_without_the_ticker_it_is_the_plain_clock() -> None:
    async def main() -> float:
        clock = PacedClock(SCALE)
        t0 = clock.now()
        time.sleep(0.05)
        return clock.now() - t0

    assert asyncio.run(main()) >= 0.05 * SCALE
