"""A certified peer that deviates, at the companion: what the companion does about attacks the
protocol alone does not stop yet (docs/security.md, "A deviating peer")."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

from companion.auth.session import AuthenticationError, Refusal
from companion.mission.ground import COVER_ALL, cut_at
from companion.runs.exchange import PeerRefused
from companion.settings import CompanionSettings
from companion.sim.virtual_time import run_simulated
from protocol.geo.grid import GridSpec
from protocol.messages import Suite
from tests.companion.attacks.harness import World, count_bobs, world

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


HERE = (474_011_000, 85_455_940)


@pytest.mark.parametrize(
    ("centre", "radius_m", "resolution_mm"),
    [
        ((474_461_000, 85_455_940), 2000.0, 500),  # 5 km north of her beacons
        (HERE, 1_000_000.0, 1000),
        (HERE, 128_000.0, 500),
        (HERE, 2000.0, 50),
        (HERE, 2000.0, 1),
    ],
    ids=["away", "continent", "twice-the-limit", "finer-than-the-floor", "millimetre"],
)
def test_a_box_away_too_large_or_too_fine_is_refused_before_any_work(
    tmp_path: Path,
    monkeypatch: Any,
    centre: tuple[int, int],
    radius_m: float,
    resolution_mm: int,
) -> None:
    """D7: Bob's path is cut to Alice's box, so a deviating Alice who centres her grid on
    somebody's delivery address, kilometres from where her signed beacons put her, would
    probe where Bob flies there -- and so would a box centred on her but a thousand
    kilometres wide; a grid finer than Bob's floor places his vertices more precisely than he
    agreed to.  Bob refuses each (signed, BOX) before he builds anything; a request centred
    where she is and within his limits (64 km, 100 mm by default) gets its answer."""
    built = count_bobs(monkeypatch)

    async def main() -> tuple[World, list[Any]]:
        w = await world(tmp_path, missions={2: "inspection_north.plan"}, extra={9: "fleet"})
        rogue = await w.rogue(9)
        await rogue.announce(w, HERE, size_class=2)
        outcomes: list[Any] = []
        for grid in (
            GridSpec.geo(*centre, radius_m=radius_m, resolution_mm=resolution_mm),
            GridSpec.geo(*HERE, radius_m=64_000.0, resolution_mm=100),  # at both limits
        ):
            try:
                outcomes.append(await rogue.compare(w, 2, ((0, 0), (10, 0), (10, 10)), grid))
            except PeerRefused as exc:
                outcomes.append(exc)
        await w.stop()
        return w, outcomes

    w, (probe, within) = run_simulated(main())
    assert isinstance(probe, PeerRefused) and probe.code is Refusal.BOX
    assert not isinstance(within, Exception)  # the honest-looking request is answered
    assert len(built) == 1  # Bob built his machine for the second request only
    assert [e["reason"] for e in w.events(2, "refused")] == ["BOX"]


@pytest.mark.parametrize(
    ("jump", "wait_s", "answered"),
    [
        ((474_461_000, 85_455_940), 5.0, False),  # 5 km north, 10 s after the last beacon
        ((474_461_000, 85_455_940), 130.0, True),  # the same, 2 minutes later: 40 m/s flies it
        ((478_511_000, 85_455_940), 5.0, False),  # 50 km north: beyond any track, and radio
    ],
    ids=["5-km-jump", "5-km-flown", "50-km"],
)
def test_a_box_at_a_beacon_that_jumped_is_refused(
    tmp_path: Path,
    monkeypatch: Any,
    jump: tuple[int, int],
    wait_s: float,
    answered: bool,
) -> None:
    """D7, by the track: the prober's signed beacons put it here, then one signed beacon puts
    it where it wants to probe, and it asks for a box centred there.  Before, Bob checked the
    box against her last beacon only and answered.  Now her box must be where her track of
    beacons makes plausible (200 m, plus 40 m/s since the track's last plausible point) and
    within 30 km of Bob: a jump no drone can fly is refused (signed, BOX) before any work; the
    same place reached at a plausible speed is answered."""
    built = count_bobs(monkeypatch)

    async def main() -> tuple[World, Any]:
        w = await world(tmp_path, missions={2: "inspection_north.plan"}, extra={9: "fleet"})
        rogue = await w.rogue(9)
        await rogue.announce(w, HERE, size_class=2)
        await w.clock.sleep(wait_s)
        await rogue.announce(w, jump, size_class=2)
        grid = GridSpec.geo(*jump, radius_m=2000.0)
        try:
            outcome: Any = await rogue.compare(w, 2, ((0, 0), (10, 0), (10, 10)), grid)
        except PeerRefused as exc:
            outcome = exc
        await w.stop()
        return w, outcome

    w, outcome = run_simulated(main())
    if answered:
        assert not isinstance(outcome, Exception) and len(built) == 1
    else:
        assert isinstance(outcome, PeerRefused) and outcome.code is Refusal.BOX and not built
        assert [e["reason"] for e in w.events(2, "refused")] == ["BOX"]


def test_a_run_ended_after_bobs_first_reply_counts(tmp_path: Path) -> None:
    """D8: Bob's first reply shows his padded size n (in a near run, the bucket of his
    segments within the horizon Alice picked).  A certified Alice who ends each run as soon
    as she has it -- 42 such runs told one her distances to Bob's vertices 2, 4 and 8 within
    1 m -- was refunded every time, her budget untouched.  Now a run counts from Bob's first
    reply on: three such runs spend three of her runs, and her fourth ... ninth are refused
    once the hour's budget (8) is used up."""
    from protocol.errors import ProtocolError
    from protocol.intersection import Alice

    class Quits(Alice):
        def receive(self, data: bytes) -> bytes | None:
            if self.n is None:
                super().receive(data)
                raise ProtocolError("n seen: the prober ends the run")
            return super().receive(data)

    async def main() -> tuple[int, list[str]]:
        w = await world(tmp_path, missions={2: "inspection_north.plan"}, extra={9: "fleet"})
        rogue = await w.rogue(9)
        await rogue.announce(w, HERE, size_class=2)
        grid = GridSpec.geo(*HERE, radius_m=2000.0)
        ends = []
        for _ in range(9):
            try:
                await rogue.compare(w, 2, ((0, 0), (10, 0), (10, 10)), grid, machine=Quits)
                ends.append("result")
            except PeerRefused as exc:
                ends.append(exc.code.name)
            except ProtocolError:
                ends.append("quit")
            await w.clock.sleep(10)
        counted = w.drones[2].store.count_runs(0, "bob")
        await w.stop()
        return counted, ends

    counted, ends = run_simulated(main())
    assert ends == ["quit"] * 8 + ["BUDGET"], ends
    assert counted == 8


def test_near_runs_show_listeners_nothing_of_bobs_path(tmp_path: Path) -> None:
    """D8 on the air: a near run's size is a function of Bob's n.  Before, Bob answered with
    his segments within Alice's horizon, padded to a power of two, so anybody on the channel
    read from the size of every message of his how many of his segments lie within the
    distance she picked (here, with a fresh OT setup: a first reply of 6,839 bytes for a
    horizon of 100 m, 9,526 for 700 m and 3 km).  Now he answers with exactly as many
    segments as she asks for (``Hello.n``; asked none, as many as she compares): every
    message of his has the same size whatever the horizon, and how far the horizon reaches
    beyond them goes to Alice alone, sealed -- their cover of it, in eighths, counted in the
    run budget like the run itself."""

    async def main() -> tuple[dict[tuple[int, int], tuple[list[int], int]], int]:
        w = await world(tmp_path, missions={2: "inspection_north.plan"}, extra={9: "fleet"})
        rogue = await w.rogue(9)
        await rogue.announce(w, HERE, size_class=2)
        grid = GridSpec.geo(*HERE, radius_m=2000.0)
        seen = {}
        for ask in (0, 4):
            for horizon in (100, 700, 3000):
                report, sizes = await rogue.compare(
                    w, 2, ((0, 0), (10, 0), (10, 10)), grid, horizon_m=horizon, ask_n=ask
                )
                seen[ask, horizon] = (sizes, report.cover)
                await w.clock.sleep(10)
        within = {  # Bob's segments within each horizon, as the old near cut counted them
            h: len(cut_at(w.drones[2].flight.remaining_flown()[1], h)) - 1 for _, h in seen
        }
        await w.stop()
        return seen, len(set(within.values()))

    seen, differ = run_simulated(main())
    assert differ > 1  # the horizons reach different numbers of Bob's segments
    for ask in (0, 4):
        assert len({tuple(s) for (a, _), (s, _) in seen.items() if a == ask}) == 1, seen
    covers = [cover for (a, _), (_, cover) in seen.items() if a == 0]  # two segments
    assert covers[0] == COVER_ALL and covers[-1] < covers[1] < COVER_ALL, covers
    assert seen[4, 700][0][0] > seen[0, 700][0][0]  # four segments are more bytes


def test_a_size_asked_beyond_a_fair_run_or_of_a_full_run_is_refused(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """``Hello.n`` is Alice's to choose: a near run asking Bob to pad his answer to 256
    segments would make him work for a run far beyond a fair one, and a full run asking for
    a size would cut his path where he must show all of it.  Both are refused (signed,
    SIZE) before any work; a near run asking for four is answered."""
    built = count_bobs(monkeypatch)

    async def main() -> tuple[World, list[Any]]:
        w = await world(tmp_path, missions={2: "inspection_north.plan"}, extra={9: "fleet"})
        rogue = await w.rogue(9)
        await rogue.announce(w, HERE, size_class=2)
        grid = GridSpec.geo(*HERE, radius_m=2000.0)
        outcomes: list[Any] = []
        for horizon, ask in ((500, 256), (0, 2), (500, 4)):
            try:
                report, _ = await rogue.compare(
                    w, 2, ((0, 0), (10, 0), (10, 10)), grid, horizon_m=horizon, ask_n=ask
                )
                outcomes.append(report)
            except PeerRefused as exc:
                outcomes.append(exc.code)
            await w.clock.sleep(10)
        await w.stop()
        return w, outcomes

    w, (padded, full, fair) = run_simulated(main())
    assert padded is Refusal.SIZE and full is Refusal.SIZE
    assert not isinstance(fair, Refusal) and len(built) == 1
    assert [e["reason"] for e in w.events(2, "refused")] == ["SIZE", "SIZE"]


def test_a_cover_out_of_range_ends_the_run(tmp_path: Path, monkeypatch: Any) -> None:
    """Bob's cover of the horizon (eighths, 0..8) is his to say: one above 8 would have
    Alice hold her near run's decisions beyond anything he showed.  It ends the run as an
    authentication failure, before any of his reply is used: no result, no edit."""
    import companion.runs.bob as bob_module

    honest = bob_module.BobAnswers._bob_path

    def inflated(self: Any, hello: Any, cover: Any) -> Any:
        route = honest(self, hello, cover)
        cover.eighths = 9
        return route

    monkeypatch.setattr(bob_module.BobAnswers, "_bob_path", inflated)

    async def main() -> World:
        w = await world(tmp_path, missions={2: "inspection_north.plan"}, extra={9: "fleet"})
        rogue = await w.rogue(9)
        await rogue.announce(w, HERE, size_class=2)
        grid = GridSpec.geo(*HERE, radius_m=2000.0)
        with pytest.raises(AuthenticationError, match="cover 9"):
            await rogue.compare(w, 2, ((0, 0), (10, 0), (10, 10)), grid, horizon_m=500)
        await w.stop()
        return w

    run_simulated(main())


def test_an_honest_box_beyond_the_peers_limit_is_refused_and_said_so(tmp_path: Path) -> None:
    """The other side of D7's limits: an honest drone whose path needs a larger box than its
    peer answers in is refused (signed, BOX), never applies a result, and its failed run says
    which box it asked for, so that an operator can see which limit to raise."""

    async def main() -> World:
        w = await world(tmp_path, settings={"max_box_radius_m": 400.0})  # below every box
        await w.clock.sleep(1800)
        await w.stop()
        return w

    w = run_simulated(main())
    failed = [e for e in w.events(1, "run_failed") if e.get("refused") == "BOX"]
    resolution = CompanionSettings(node=1, autopilot_url="").grid_resolution_mm
    assert failed and all(
        e["box_radius_m"] >= 500 and e["resolution_mm"] == resolution for e in failed
    )
    assert not w.events(1, "result") and not w.autopilots[1].uploads
    assert "BOX" in {e["reason"] for e in w.events(2, "refused")}
    assert not w.events(2, "answered")


def test_a_bob_whose_ot_extension_fails_the_check_loses_the_setup(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """D4: drone 2 (Bob) flips a bit of its OT extension in three runs -- a selective-failure
    probe of drone 1's Delta.  Drone 1's consistency check refuses each such run before any
    key is made, reports no result and keeps no setup, so no guess is ever tried twice on
    one Delta; once drone 2 behaves, a fresh setup gives the answer."""
    import protocol.compact.suite as compact
    from protocol.ot.extension import chooser_extend
    from protocol.ot.setup import HolderSetupStart

    honest = chooser_extend
    probes = {"left": 3}

    def deviating(setup: Any, nonce: bytes, count: int) -> Any:
        message, rots = honest(setup, nonce, count)
        if probes["left"] <= 0:
            return message, rots
        probes["left"] -= 1
        flipped = bytearray(message)
        flipped[0] ^= 1  # OT 0 of block 1: Alice's row gets Delta_1 only if her guess holds
        return bytes(flipped), rots

    monkeypatch.setattr(compact, "chooser_extend", deviating)
    setup_ids: list[bytes] = []
    real_finish = HolderSetupStart.finish

    def finish(self: Any, reply: bytes) -> Any:
        setup = real_finish(self, reply)
        setup_ids.append(setup.setup_id)
        return setup

    monkeypatch.setattr(HolderSetupStart, "finish", finish)

    async def main() -> World:
        w = await world(tmp_path)
        await w.clock.sleep(1800)
        await w.stop()
        return w

    w = run_simulated(main())
    deviated = [e for e in w.events(1, "run_failed") if "deviated" in e]
    assert len(deviated) == 3
    assert w.events(1, "result") and w.autopilots[1].uploads  # then the honest run's answer
    assert len(setup_ids) == len(set(setup_ids)) == 4  # a fresh setup after each failed check


@pytest.mark.parametrize("scope", ["drone", "operator"])
def test_a_deviating_alice_gets_no_more_answer_bits_than_the_budget(
    tmp_path: Path, monkeypatch: Any, scope: str
) -> None:
    """D6 (bounded): whatever a deviating Alice computes with her m output bits, Bob counts
    them, per drone and per operator.  With 16 answer bits per drone (or per operator) and
    hour, runs of 8 segments get two answers -- from one rogue drone, or from two of one
    operator -- and the third request is refused (signed, BUDGET) before Bob builds
    anything, even from a drone that has used only 8 of its own bits."""
    built = count_bobs(monkeypatch)
    here = (474_011_000, 85_455_940)

    async def main() -> tuple[World, list[Any]]:
        w = await world(
            tmp_path,
            missions={2: "inspection_north.plan"},
            extra={9: "fleet", 10: "fleet"},
            settings={"max_answer_bits_per_peer": 16} if scope == "drone" else {},
        )
        if scope == "operator":  # drone 2 trusts the rogues' operator with 16 bits an hour
            operators = w.credentials[2].trust.operators
            for fingerprint, op in operators.items():
                operators[fingerprint] = dataclasses.replace(op, max_answer_bits_per_hour=16)
        rogues = [await w.rogue(9)] + ([await w.rogue(10)] if scope == "operator" else [])
        for rogue in rogues:
            await rogue.announce(w, here, size_class=3)
        path = tuple((10 * k, 10 * (k % 2)) for k in range(9))  # 8 segments
        outcomes: list[Any] = []
        for k in range(3):
            grid = GridSpec.geo(*here, radius_m=2000)
            try:
                outcomes.append(await rogues[k % len(rogues)].compare(w, 2, path, grid))
            except PeerRefused as exc:
                outcomes.append(exc)
        await w.stop()
        return w, outcomes

    w, (first, second, third) = run_simulated(main())
    assert not isinstance(first, Exception) and not isinstance(second, Exception)
    assert isinstance(third, PeerRefused) and third.code is Refusal.BUDGET
    assert len(built) == 2
    assert [e["reason"] for e in w.events(2, "refused")] == ["BUDGET"]
    assert f"{scope} answer-bit limit" in w.events(2, "budget")[0]["error"]
