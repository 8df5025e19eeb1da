"""The path comparison through the simulated radio: ``compare --link`` and ``bench link``.

Each case runs Alice and Bob as two link endpoints (nodes 1 and 2) on one simulated channel,
on a virtual clock: airtime, duty-cycle waits, timeouts and both parties' CPU time pass as link
time, so hours of regulated airtime take a fraction of a second of real time.  Counts are real
frames (their encoded bytes on the air); airtime is the Semtech formula for each of them.
Every case starts with fresh endpoints, as the first exchange of the hour would.  Runs are
authenticated as the companion's are (:mod:`companion.auth.session`: a signed key exchange on
the first two messages, an AEAD tag on every message), between two throwaway certified
identities; ``auth_bytes`` says what that added.
"""

from __future__ import annotations

import functools
import itertools
import logging
import tempfile
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from companion.auth.session import Identity, Init, Initiator, Responder, Route
from companion.mission.files import read_mission_file
from companion.mission.flightpath import flight_path
from companion.mission.items import MissionError
from companion.radio import PROFILES, Clock, LinkConfig, LinkEndpoint, LinkProfile
from companion.runs.exchange import RunReport, run_alice, serve_bob
from companion.sim.fleet import make_fleet
from companion.sim.medium import Channel, Impairments, SimMedium
from companion.sim.virtual_time import run_simulated
from companion.tasks import spawn
from protocol.geo.grid import GridSpec
from protocol.messages import Suite
from protocol.run import Limits
from protocol.tools.compare import Case, Party, compare
from protocol.tools.demo import ALICE_MISSION, BOB_MISSION, HOME_LAT, HOME_LON
from protocol.tools.formats import InputFormatError

ALICE_NODE, BOB_NODE = 1, 2
log = logging.getLogger(__name__)


async def _run(
    case: Case,
    party: Party,
    link: LinkProfile,
    impairments: Impairments,
    seed: int | None,
    limits: Limits,
    config: LinkConfig | None,
    authenticated: bool,
) -> dict[str, Any]:
    clock = Clock(charges_cpu=True)  # both parties' CPU passes as link time
    channel = Channel(impairments, seed)
    medium = SimMedium(channel, clock)
    a = LinkEndpoint(ALICE_NODE, medium.attach(ALICE_NODE), link, config, clock)
    b = LinkEndpoint(BOB_NODE, medium.attach(BOB_NODE), link, config, clock)
    alice, bob = case.machines(party, limits)
    fleet = _identities() if authenticated else None
    async with a, b:

        async def bob_side() -> RunReport:
            peer, session = await b.accept()
            if fleet is None:
                return await serve_bob(b, peer, session, bob)
            init = Init.parse(await b.receive(peer, session))
            responder = Responder(fleet[1], init, Route(peer, BOB_NODE, session))
            responder.verify(fleet[0].cert, b.arrived(peer, session), 30.0, link.budget_wait_s)
            return await serve_bob(
                b, peer, session, bob, secure=responder, boot=bytes(16),
                first=init.hello,
            )  # fmt: skip

        def secure(session: int) -> Initiator:
            assert fleet is not None
            route = Route(ALICE_NODE, BOB_NODE, session)
            return Initiator(fleet[0], fleet[1].cert, route, clock.wall())

        bob_task = spawn(bob_side(), name="bob", log=log)  # logged even if Alice fails first
        try:
            report = await run_alice(a, BOB_NODE, alice, secure=secure if fleet else None)
        except BaseException:
            bob_task.cancel()
            raise
        bob_report = await bob_task
    return _result(case, report, bob_report, a, b, channel)


def _result(
    case: Case,
    report: RunReport,
    bob_report: RunReport,
    a: LinkEndpoint,
    b: LinkEndpoint,
    channel: Channel,
) -> dict[str, Any]:
    """One case's figures: both parties' reports and both endpoints' and the channel's stats."""
    stats = (a.stats, b.stats)
    return {
        "hits": report.hits,
        "plain_hits": case.plain_hits(),
        "bytes_alice_to_bob": report.bytes_sent,
        "bytes_bob_to_alice": bob_report.bytes_sent,
        "auth_bytes": report.auth_bytes_sent + bob_report.auth_bytes_sent,
        "messages": report.messages_sent + bob_report.messages_sent,
        "round_trips": report.messages_sent,  # each of Alice's messages is one turn
        "cpu_s_alice": report.cpu_s,
        "cpu_s_bob": bob_report.cpu_s,
        "frames_sent": sum(s.frames_sent for s in stats),
        "frames_retransmitted": sum(s.frames_retransmitted for s in stats),
        "polls": sum(s.polls_sent for s in stats),
        "bytes_on_air": sum(s.bytes_sent for s in stats),
        "airtime_s": sum(s.airtime_s for s in stats),
        "duty_wait_s": sum(s.duty_wait_s for s in stats),
        "wall_s_simulated": report.wall_s,
        "frames_dropped": _merge(a.stats.dropped, b.stats.dropped),
        "channel": asdict(channel.stats),
    }


@functools.cache
def _identities() -> tuple[Identity, Identity]:
    """Alice's and Bob's certified identities for benchmark runs (made once per process)."""
    with tempfile.TemporaryDirectory() as state:
        fleet = make_fleet([(ALICE_NODE, "a"), (BOB_NODE, "b")], Path(state))
    return fleet[ALICE_NODE].identity, fleet[BOB_NODE].identity


def _merge(*counters: dict[str, int]) -> dict[str, int]:
    merged: dict[str, int] = {}
    for counter in counters:
        for key, value in counter.items():
            merged[key] = merged.get(key, 0) + value
    return merged


def link_case(
    case: Case,
    party: Party,
    link: LinkProfile,
    impairments: Impairments | None = None,
    seed: int | None = None,
    limits: Limits | None = None,
    config: LinkConfig | None = None,
    *,
    authenticated: bool = True,
) -> dict[str, Any]:
    """One comparison through the simulated link (virtual time); ``authenticated=False``
    sends the protocol's messages in the clear (to measure what authentication adds)."""
    return run_simulated(
        _run(
            case,
            party,
            link,
            impairments or Impairments(),
            seed,
            limits or Limits(),
            config,
            authenticated,
        )
    )


def duration_text(seconds: float) -> str:
    """Seconds, minutes or hours, whichever reads best."""
    if seconds < 120:
        return f"{seconds:.1f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def flown_points(path: Path) -> tuple[tuple[int, int], ...]:
    """The ground path a mission file flies (degE7), from its home: the one model
    (:mod:`companion.mission.flightpath`) the companion compares in flight.  File errors are
    :class:`InputFormatError` (exit 2)."""
    try:
        mission = read_mission_file(path)
        return tuple(flight_path(mission.for_autopilot(), mission.home_degE7).points)
    except MissionError as exc:
        raise InputFormatError(str(exc)) from exc


def compare_over_link(
    alice_file: str | Path,
    bob_file: str | Path,
    suite_name: str,
    link: LinkProfile,
    impairments: Impairments,
    seed: int | None,
    *,
    range_: int | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """``compare --link``: the plain comparison's JSON plus the link's counters per case."""
    seeds = itertools.count(1)

    def over_link(case: Case, party: Party) -> dict[str, Any]:
        number = next(seeds)
        return link_case(case, party, link, impairments, None if seed is None else seed + number)

    result = compare(
        alice_file,
        bob_file,
        suite_name,
        range_=range_,
        progress=progress,
        run=over_link,
        read_mission=flown_points,
    )
    result["link"] = {
        "profile": link.name,
        **asdict(impairments),
        "seed": seed,
        "frame_bytes": link.max_frame,
    }
    return result


def radio_demo(profiles: Sequence[str] = ("eu868-sf7", "us915-sf7"), loss: float = 0.1) -> int:
    """The demo's two missions once more, through the simulated radio (``make demo``)."""
    grid = GridSpec.geo(HOME_LAT, HOME_LON, radius_m=2000)
    case = Case.of(grid.project_path(ALICE_MISSION), BOB_MISSION, grid, bob_geographic=True)
    party = Party.generate(Suite.COMPACT)
    print(f"\nThe same comparison over the simulated LoRa link ({loss:.0%} frame loss, same seed):")
    print("\n| profile | correct | frames | retransmitted | airtime | simulated time |")
    print("|---|---|---:|---:|---:|---:|")
    ok = True
    for name in profiles:
        r = link_case(case, party, PROFILES[name], Impairments(loss=loss), seed=1)
        ok &= r["hits"] == r["plain_hits"]
        print(
            f"| {name} | {r['hits'] == r['plain_hits']} | {r['frames_sent']} "
            f"| {r['frames_retransmitted']} | {duration_text(r['airtime_s'])} "
            f"| {duration_text(r['wall_s_simulated'])} |"
        )
    print(
        "Under the EU868 1 % duty cycle a drone may transmit 36 s per hour: bytes, not CPU, "
        "decide what is practical on LoRa."
    )
    return 0 if ok else 1
