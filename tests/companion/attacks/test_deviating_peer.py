"""A certified peer that deviates, at the companion: what the companion does about attacks the
protocol alone does not stop yet (docs/security.md, "A deviating peer")."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.link import run_simulated
from protocol.wire import Suite

from .harness import World, world

pytestmark = [pytest.mark.attack, pytest.mark.deviating]


def test_the_paper_suite_runs_only_with_operators_trusted_with_its_keys(tmp_path: Path) -> None:
    """D3: a Bob with out-of-range encryptions (or malformed keys) could read Alice's path in
    one paper-suite run.  Without ``paper_keys`` for his operator, drone 1 never starts one:
    no request goes out, the run is recorded as failed (and retried: the fail-safe keeps
    watching the peer); with it, the same encounter gives a result."""

    async def main(trusted: bool) -> World:
        w = await world(
            tmp_path / str(trusted), settings={"suite": Suite.PAPER}, paper_keys=trusted
        )
        await w.clock.sleep(1800)
        await w.stop()
        return w

    refused = run_simulated(main(False))
    failed = refused.events(1, "run_failed")
    assert failed and all("paper_keys" in f.get("error", "") for f in failed)
    assert not refused.events(1, "result") and not refused.autopilots[1].uploads
    assert not refused.events(2, "answered") and not refused.events(2, "answer_failed")
    assert not refused.events(1, "run_started")  # not a byte of a run was sent
    trusted = run_simulated(main(True))
    assert trusted.events(1, "result") and trusted.autopilots[1].uploads
