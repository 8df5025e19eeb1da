"""The path-comparison protocol over the simulated radio (virtual time)."""

from __future__ import annotations

import asyncio

import pytest

from companion.radio import PROFILES, LinkConfig, LinkTimeout, PeerAborted
from companion.runs.exchange import run_alice, serve_bob
from companion.sim.medium import Impairments
from companion.sim.over_link import link_case
from companion.sim.virtual_time import run_simulated
from protocol.errors import RemoteProtocolError
from protocol.geo.geometry import path_hits
from protocol.geo.grid import GridKind, GridSpec
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.run import State
from protocol.tools.compare import Case, Party, run_case
from tests.companion.radio.helpers import pair

HARSH = Impairments(loss=0.3, corrupt=0.05, duplicate=0.02, reorder=0.1)
GRID = GridSpec(GridKind.PLANE, 40)
CROSSING = Case.of(((-30, 0), (0, 5), (30, 0)), ((0, -30), (1, 30)), GRID)
COLLINEAR = Case.of(((-30, -30), (30, 30)), ((0, 0), (40, 40)), GRID)
APART = Case.of(((-30, -30), (-20, -30), (-10, -25)), ((10, 10), (20, 30)), GRID)


@pytest.fixture(scope="module")
def compact() -> Party:
    return Party.generate(Suite.COMPACT)


@pytest.fixture(scope="module")
def paper() -> Party:
    return Party.generate(Suite.PAPER)


@pytest.mark.parametrize("case", [CROSSING, COLLINEAR, APART], ids=["cross", "collinear", "apart"])
@pytest.mark.parametrize("name", ["eu868-sf7", "us915-sf9", "ideal"])
def test_correct_under_30_percent_loss_with_corruption_and_reordering(
    compact: Party, case: Case, name: str
) -> None:
    impaired = {"corrupted": 0, "reordered": 0, "frames_retransmitted": 0}
    for seed in range(11, 19):  # a run is a few dozen frames: several seeds see every fault
        result = link_case(case, compact, PROFILES[name], HARSH, seed=seed)
        assert (
            result["hits"] == path_hits(case.alice.points, case.bob.points) == result["plain_hits"]
        )
        assert result["messages"] == run_case(case, compact)["messages"]  # as without the radio
        impaired["frames_retransmitted"] += result["frames_retransmitted"]
        for key in ("corrupted", "reordered"):
            impaired[key] += result["channel"][key]
    assert all(count > 0 for count in impaired.values()), impaired


@pytest.mark.slow
def test_paper_suite_under_30_percent_loss(paper: Party) -> None:
    for seed, case in enumerate([CROSSING, COLLINEAR]):
        result = link_case(case, paper, PROFILES["eu868-sf9"], HARSH, seed=seed)
        assert result["hits"] == result["plain_hits"]


def test_accounting_is_consistent(compact: Party) -> None:
    r = link_case(CROSSING, compact, PROFILES["eu868-sf7"], Impairments(), seed=1)
    assert r["frames_retransmitted"] == 0 and r["polls"] == 0
    messages = r["bytes_alice_to_bob"] + r["bytes_bob_to_alice"]
    # Every message byte goes on the air once, plus 16 bytes per frame and the ACK payloads.
    assert messages < r["bytes_on_air"] < messages + 16 * r["frames_sent"] + 40 * 8
    # About 5.5 kbit/s at SF7 for the payload, plus the preamble and header of each frame
    # (12.25 + up to 8 symbols of 1.024 ms): small frames pay relatively more.
    payload_s = r["bytes_on_air"] * 8 / 5470
    assert payload_s < r["airtime_s"] < payload_s + 0.03 * r["frames_sent"]
    assert r["wall_s_simulated"] >= r["airtime_s"] / 2  # both talk, one at a time mostly


def _machines(party: Party, case: Case) -> tuple[Alice, Bob]:
    return case.machines(party)


def test_peer_vanishing_mid_run_ends_in_a_known_state(compact: Party) -> None:
    alice, bob = _machines(compact, CROSSING)

    async def main() -> None:
        async with pair(PROFILES["us915-sf7"], config=LinkConfig(idle_timeout_s=60)) as p:

            async def bob_side() -> None:
                peer, session = await p.b.accept()
                message = await p.b.receive(peer, session)
                bob.receive(message)  # computes the reply ... and the drone flies away
                await p.b.close()

            task = asyncio.create_task(bob_side())
            with pytest.raises(LinkTimeout):
                await run_alice(p.a, 2, alice)
            await task
            assert p.a.receiver.pending() == 0
            assert not p.a.open_sessions

    run_simulated(main())
    assert alice.state is State.FAILED


def test_a_malformed_message_aborts_both_sides(compact: Party) -> None:
    _, bob = _machines(compact, CROSSING)

    async def main() -> None:
        async with pair(PROFILES["ideal"]) as p:

            async def bob_side() -> None:
                peer, session = await p.b.accept()
                with pytest.raises(RemoteProtocolError):
                    await serve_bob(p.b, peer, session, bob)

            task = asyncio.create_task(bob_side())
            session = p.a.open(2)
            await p.a.send(2, session, b"PD\x01\x01garbage")
            with pytest.raises(PeerAborted, match="code 1"):
                await p.a.receive(2, session)
            await task
            assert not p.b.open_sessions

    run_simulated(main())
    assert bob.state is State.FAILED


def test_run_time_limit(compact: Party) -> None:
    alice, bob = _machines(compact, CROSSING)

    async def main() -> None:
        async with pair(PROFILES["eu868-sf12"]) as p:

            async def bob_side() -> None:
                peer, session = await p.b.accept()
                with pytest.raises(PeerAborted, match="timeout"):
                    await serve_bob(p.b, peer, session, bob)

            task = asyncio.create_task(bob_side())
            with pytest.raises(LinkTimeout, match="exceeded its 600 s limit"):
                await run_alice(p.a, 2, alice, timeout=600)
            await task

    run_simulated(main())
    assert alice.state is State.FAILED and bob.state is State.FAILED
