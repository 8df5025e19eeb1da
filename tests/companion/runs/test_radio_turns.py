"""Who gets the radio: a drone busy with its own run refuses a request at once (signed BUSY)
and is asked again a few seconds later -- a drone kept waiting would keep its own radio
idle, and a chain of drones each waiting on the next is as slow as all its runs together
(companion/runs/turns.py).  Real link, runtime and sessions, in virtual time."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from companion.sim.virtual_time import run_simulated
from tests.companion.attacks.harness import World, world


class _WaitingRun:
    """Our own run on the air, still waiting for its peer's first reply."""

    n = None


def test_a_peer_busy_with_its_own_run_is_asked_again_soon(tmp_path: Path) -> None:
    async def main() -> tuple[World, float]:
        w = await world(tmp_path)
        bob = w.drones[2]
        bob.air.own = _WaitingRun()  # type: ignore[assignment]
        while not w.events(1, "peer_busy"):
            await w.clock.sleep(1)
        busy_at = w.clock.now() - w.drones[1].epoch
        await w.clock.sleep(2)
        bob.air.own = None  # its own run is over
        while not w.events(1, "result"):
            await w.clock.sleep(1)
        await w.clock.sleep(5)
        await w.stop()
        return w, busy_at

    w, busy_at = run_simulated(main())
    assert [r["reason"] for r in w.events(2, "refused")] == ["BUSY"]  # signed, before any work
    assert not w.events(1, "run_failed")  # a busy peer is no failure
    starts = [e.t for e in w.drones[1].events if e.kind == "run_started"]
    low, high = w.drones[1].settings.busy_retry_s
    again = [t for t in starts if t > busy_at]
    assert again and busy_at + low - 1 <= again[0] <= busy_at + high + 1  # soon, not 30 s
    (result,) = w.events(1, "result")
    assert result["flagged"] == [0]  # the crossing, found once the peer was free


def test_a_request_waits_behind_a_run_under_way(tmp_path: Path) -> None:
    """A run of ours that its peer already answers is under way: a request waits for it
    (answers go first once the radio is free) instead of being refused."""

    class Answered:
        n = 4  # the peer's first reply came: its size is known

    async def main() -> World:
        w = await world(tmp_path)
        bob = w.drones[2]
        bob.air.own = Answered()  # type: ignore[assignment]
        turn: Any = bob.air.turns.turn(3)  # our own run holds the radio
        await turn.__aenter__()
        await w.clock.sleep(60)
        assert not w.events(1, "result") and not w.events(2, "refused")
        bob.air.own = None
        await turn.__aexit__(None, None, None)
        while not w.events(1, "result"):
            await w.clock.sleep(1)
        await w.stop()
        return w

    w = run_simulated(main())
    assert not w.events(1, "peer_busy") and not w.events(2, "refused")
    assert w.events(1, "result")[0]["flagged"] == [0]
