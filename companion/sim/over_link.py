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

import asyncio
import dataclasses
import functools
import itertools
import statistics
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from protocol.geometry import path_hits
from protocol.grid import GridKind, GridSpec
from protocol.intersection import Limits
from protocol.tools.bench_paths import DEFAULT_DATA, random_path
from protocol.tools.compare import Case, Party, compare, load_cases
from protocol.tools.formats import InputFormatError
from protocol.wire import Suite

from ..auth.session import Identity, Init, Initiator, Responder, Route
from ..beacon_budget import beacon_costs
from ..exchange import RunReport, run_alice, serve_bob
from ..flightpath import flight_path
from ..link import (
    PROFILES,
    Channel,
    Clock,
    Impairments,
    LinkConfig,
    LinkEndpoint,
    LinkProfile,
    SimMedium,
    profile,
    run_simulated,
)
from ..link.frames import OVERHEAD
from ..mission import MissionError
from ..missionfile import read_mission_file
from .fleet import make_fleet

ALICE_NODE, BOB_NODE = 1, 2


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
    clock = Clock()
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
                return await serve_bob(b, peer, session, bob, charge_cpu=True)
            init = Init.parse(await b.receive(peer, session))
            responder = Responder(fleet[1], init, Route(peer, BOB_NODE, session))
            responder.verify(fleet[0].cert, b.arrived(peer, session), 30.0, link.budget_wait_s)
            return await serve_bob(
                b, peer, session, bob, secure=responder, boot=bytes(16), charge_cpu=True,
                first=init.hello,
            )  # fmt: skip

        def secure(session: int) -> Initiator:
            assert fleet is not None
            route = Route(ALICE_NODE, BOB_NODE, session)
            return Initiator(fleet[0], fleet[1].cert, route, clock.wall())

        bob_task = asyncio.create_task(bob_side())
        try:
            report = await run_alice(
                a, BOB_NODE, alice, secure=secure if fleet else None, charge_cpu=True
            )
        except BaseException:
            bob_task.cancel()
            raise
        bob_report = await bob_task
    stats = (a.stats, b.stats)
    return {
        "hits": report.hits,
        "plain_hits": path_hits(case.alice, case.bob_on_grid),
        "bytes_alice_to_bob": report.bytes_sent,
        "bytes_bob_to_alice": bob_report.bytes_sent,
        "auth_bytes": report.auth_bytes_sent + bob_report.auth_bytes_sent,
        "messages": report.messages_sent + bob_report.messages_sent,
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


# ---------------------------------------------------------------------------- bench link

LOSSES = (0.0, 0.1, 0.3)


def _say(progress: bool, message: str) -> None:
    if progress:
        print(f"  ... {message}", file=sys.stderr, flush=True)


def _row(
    profile_name: str, loss: float, workload: str, runs: list[dict[str, Any]]
) -> dict[str, Any]:
    def med(key: str) -> float:
        return float(statistics.median(r[key] for r in runs))

    return {
        "profile": profile_name,
        "loss": loss,
        "workload": workload,
        "runs": len(runs),
        "correct": sum(r["hits"] == r["plain_hits"] for r in runs),
        "frames_sent": med("frames_sent"),
        "frames_retransmitted": med("frames_retransmitted"),
        "bytes_on_air": med("bytes_on_air"),
        "auth_bytes": med("auth_bytes"),
        "message_bytes": med("bytes_alice_to_bob") + med("bytes_bob_to_alice"),
        "airtime_s": med("airtime_s"),
        "wall_s_simulated": med("wall_s_simulated"),
        "cpu_s": med("cpu_s_alice") + med("cpu_s_bob"),
    }


def bench_link(
    data: Path = DEFAULT_DATA,
    profiles: Sequence[str] | None = None,
    losses: Sequence[float] = LOSSES,
    suite: str = "compact",
    size: int = 8,
    range_: int = 99,
    seed: int = 1,
    progress: bool = True,
) -> dict[str, Any]:
    """The paper's 30 pairs and one size x size random case over each profile and loss."""
    if not (data / "alices_segments.txt").exists():
        raise InputFormatError(f"no benchmark data in {data} (use --data DIR)")
    profiles = list(profiles or PROFILES)
    for name in profiles:
        profile(name)  # unknown names fail before any work
    _say(progress, f"generating keys ({suite})")
    party = Party.generate(Suite.COMPACT if suite == "compact" else Suite.PAPER)
    pairs = load_cases(data / "alices_segments.txt", data / "bobs_segments.txt")
    grid = GridSpec(GridKind.PLANE, range_)
    paths = Case(random_path(size, range_), random_path(size, range_), grid)
    rows = []
    for name in profiles:
        link = PROFILES[name]
        for loss in losses:
            imp = Impairments(loss=loss)
            _say(progress, f"{name}, loss {loss:.0%}: paper pairs")
            runs = [link_case(c, party, link, imp, seed + k) for k, c in enumerate(pairs)]
            rows.append(_row(name, loss, "paper pair", runs))
            if party.setup is not None:  # two drones that never met: a fresh OT setup
                _say(progress, f"{name}, loss {loss:.0%}: paper pairs, first contact")
                fresh = dataclasses.replace(party, setup=None, setups={})
                runs = [
                    link_case(c, dataclasses.replace(fresh, setups={}), link, imp, seed + k)
                    for k, c in enumerate(pairs)
                ]
                rows.append(_row(name, loss, "paper pair, first contact", runs))
            _say(progress, f"{name}, loss {loss:.0%}: {size} x {size} paths")
            rows.append(
                _row(name, loss, f"{size}x{size}", [link_case(paths, party, link, imp, seed)])
            )
    return {
        "suite": suite,
        "profiles": {
            n: {
                "description": PROFILES[n].description,
                "frame_bytes": PROFILES[n].max_frame,
                "payload_bytes": PROFILES[n].max_frame - OVERHEAD,
                "frame_airtime_s": PROFILES[n].airtime(PROFILES[n].max_frame),
                "header_share_of_airtime": header_share(PROFILES[n]),
                "duty_cycle": PROFILES[n].duty_cycle,
                "dwell_s": PROFILES[n].dwell_s,
            }
            for n in profiles
        },
        "grid_range": range_,
        "rows": rows,
        "beacons": {n: [asdict(c) for c in beacon_costs(PROFILES[n])] for n in profiles},
    }


def header_share(link: LinkProfile) -> float:
    """Share of a full frame's airtime spent on the link header and CRC."""
    full = link.airtime(link.max_frame)
    return (full - link.airtime(link.max_frame - OVERHEAD)) / full


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.1f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def format_link(result: dict[str, Any]) -> str:
    lines = [
        f"Link benchmark, suite {result['suite']}: medians per run; a paper pair is one "
        f"1 x 1 comparison (keys included; the compact suite's one-time OT setup made before, "
        f"as between drones that met; 'first contact': with a fresh OT setup), "
        f"{result['rows'][-1]['workload']} one run (a single run, range "
        f"+-{result['grid_range']}).",
        "",
        "| profile | frame B | header share of airtime | duty cycle | dwell |",
        "|---|---:|---:|---|---|",
    ]
    for name, p in result["profiles"].items():
        duty = f"{p['duty_cycle']:.0%}" if p["duty_cycle"] else "none"
        dwell = f"{p['dwell_s'] * 1000:.0f} ms" if p["dwell_s"] else "none"
        share = p["header_share_of_airtime"]
        lines.append(f"| {name} | {p['frame_bytes']} | {share:.1%} | {duty} | {dwell} |")
    lines += [
        "",
        "Runs are authenticated (signed key exchange on the first two messages, a 16-byte tag "
        "on every message): 'auth B' is what that adds to the protocol's messages, and its "
        "share of them.",
        "",
        "| profile | loss | workload | correct | frames | retransmitted | frames vs 0 % "
        "| auth B | airtime | simulated time |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    base: dict[tuple[str, str], float] = {}
    for r in result["rows"]:
        key = (r["profile"], r["workload"])
        if r["loss"] == 0:
            base[key] = r["frames_sent"]
        ratio = r["frames_sent"] / base[key] if key in base else float("nan")
        added = r["auth_bytes"] / (r["message_bytes"] - r["auth_bytes"])
        lines.append(
            f"| {r['profile']} | {r['loss']:.0%} | {r['workload']} | {r['correct']}/{r['runs']} "
            f"| {r['frames_sent']:.0f} | {r['frames_retransmitted']:.0f} | {ratio:.2f}x "
            f"| {r['auth_bytes']:.0f} (+{added:.1%}) "
            f"| {_duration(r['airtime_s'])} | {_duration(r['wall_s_simulated'])} |"
        )
    lines += [
        "",
        "Beacons (payload bytes, frames, airtime each; share: of the channel's time, or of the "
        "duty-cycle budget under EU868, if every beacon at the profile's interval -- 10 s, "
        "stretched under a duty cycle -- were of that kind; most are tagged, a signed one goes "
        "out at the start, when a new drone is heard and every 5 minutes (or 30th beacon), "
        "certificates when asked for):",
        "",
        "| profile | beacon | bytes | frames | airtime | share |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for name, costs in result["beacons"].items():
        for c in costs:
            lines.append(
                f"| {name} | {c['kind']} | {c['payload_bytes']} | {c['frames']} "
                f"| {c['airtime_s'] * 1000:.0f} ms | {c['share']:.1%} |"
            )
    return "\n".join(lines)


def flown_points(path: Path) -> tuple[tuple[int, int], ...]:
    """The ground path a mission file flies (degE7), from its home: the one model
    (:mod:`companion.flightpath`) the companion compares in flight.  File errors are
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
    from protocol.tools.demo import ALICE_MISSION, BOB_MISSION, HOME_LAT, HOME_LON

    grid = GridSpec.geo(HOME_LAT, HOME_LON, radius_m=2000)
    case = Case(grid.project_path(ALICE_MISSION), BOB_MISSION, grid, bob_geographic=True)
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
            f"| {r['frames_retransmitted']} | {_duration(r['airtime_s'])} "
            f"| {_duration(r['wall_s_simulated'])} |"
        )
    print(
        "Under the EU868 1 % duty cycle a drone may transmit 36 s per hour: bytes, not CPU, "
        "decide what is practical on LoRa."
    )
    return 0 if ok else 1
