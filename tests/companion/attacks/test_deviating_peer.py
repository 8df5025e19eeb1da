"""A certified peer that deviates, at the companion: what the companion does about attacks the
protocol alone does not stop yet (docs/security.md, "A deviating peer")."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from companion.auth.session import Refusal
from companion.exchange import PeerRefused
from companion.link import run_simulated
from protocol.grid import GridSpec
from protocol.wire import Suite

from .harness import World, count_bobs, world

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


def test_a_box_away_from_alices_beacons_is_refused_before_any_work(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """D6 (bounded): Bob's path is cut to Alice's box, so a deviating Alice who centres her
    grid on somebody's delivery address, kilometres from where her signed beacons put her,
    would probe where Bob flies there.  Bob refuses such a request (signed, BOX) before he
    builds anything; the same request centred where she is gets its answer."""
    built = count_bobs(monkeypatch)
    here = (474_011_000, 85_455_940)
    away = (474_461_000, 85_455_940)  # 5 km north

    async def main() -> tuple[World, list[Any]]:
        w = await world(tmp_path, missions={2: "inspection_north.plan"}, extra={9: "fleet"})
        rogue = await w.rogue(9)
        await rogue.announce(w, here, size_class=2)
        outcomes: list[Any] = []
        for centre in (away, here):
            grid = GridSpec.geo(*centre, radius_m=2000)
            try:
                outcomes.append(await rogue.compare(w, 2, ((0, 0), (10, 0), (10, 10)), grid))
            except PeerRefused as exc:
                outcomes.append(exc)
        await w.stop()
        return w, outcomes

    w, (far, near) = run_simulated(main())
    assert isinstance(far, PeerRefused) and far.code is Refusal.BOX
    assert not isinstance(near, Exception)  # the honest-looking request is answered
    assert len(built) == 1  # Bob built his machine for the second request only
    assert [e["reason"] for e in w.events(2, "refused")] == ["BOX"]
