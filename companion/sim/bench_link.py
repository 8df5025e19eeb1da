"""``bench link``: the path comparison over every radio profile and loss, in real frames.

For each profile and frame loss: 30 single-segment pairs -- the paper's (``--data DIR``, read
by :mod:`protocol.tools.paper_data`) or, without it, 30 random pairs of the same shape -- with
the OT setup cached and at first contact, and one random size x size case, each through
:func:`~.over_link.link_case` on the virtual clock; medians per run of frames, bytes on the
air, authentication bytes, airtime, simulated time and both parties' CPU.  Also each profile's
frame sizes and header share, and what beacons cost
(:func:`companion.neighbours.beacon_airtime.beacon_costs`).
"""

from __future__ import annotations

import dataclasses
import statistics
import sys
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from companion.neighbours.beacon_airtime import beacon_costs
from companion.radio import PROFILES, LinkProfile, profile
from companion.radio.frames import OVERHEAD
from companion.sim.medium import Impairments
from companion.sim.over_link import duration_text, link_case
from protocol.geo.grid import GridKind, GridSpec
from protocol.messages import Suite
from protocol.tools.bench_paths import random_pairs, random_path
from protocol.tools.compare import Case, Party
from protocol.tools.paper_data import load_paper_data

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
    data: Path | None = None,
    profiles: Sequence[str] | None = None,
    losses: Sequence[float] = LOSSES,
    suite: str = "compact",
    size: int = 8,
    range_: int = 99,
    seed: int = 1,
    progress: bool = True,
    pairs: int | None = None,
) -> dict[str, Any]:
    """The paper's 30 pairs from ``data`` (or 30 random pairs in +-99 without it; the first
    ``pairs`` of them if given) and one size x size random case over each profile and loss."""
    cases = load_paper_data(data).pairs if data is not None else random_pairs()
    cases = cases[:pairs] if pairs is not None else cases
    kind = "paper pair" if data is not None else "random pair"
    profiles = list(profiles or PROFILES)
    for name in profiles:
        profile(name)  # unknown names fail before any work
    _say(progress, f"generating keys ({suite})")
    party = Party.generate(Suite.COMPACT if suite == "compact" else Suite.PAPER)
    grid = GridSpec(GridKind.PLANE, range_)
    paths = Case.of(random_path(size, range_), random_path(size, range_), grid)
    rows = []
    for name in profiles:
        link = PROFILES[name]
        for loss in losses:
            imp = Impairments(loss=loss)
            _say(progress, f"{name}, loss {loss:.0%}: {kind}s")
            runs = [link_case(c, party, link, imp, seed + k) for k, c in enumerate(cases)]
            rows.append(_row(name, loss, kind, runs))
            if party.setup is not None:  # two drones that never met: a fresh OT setup
                _say(progress, f"{name}, loss {loss:.0%}: {kind}s, first contact")
                fresh = dataclasses.replace(party, setup=None, setups={})
                runs = [
                    link_case(c, dataclasses.replace(fresh, setups={}), link, imp, seed + k)
                    for k, c in enumerate(cases)
                ]
                rows.append(_row(name, loss, f"{kind}, first contact", runs))
            _say(progress, f"{name}, loss {loss:.0%}: {size} x {size} paths")
            rows.append(
                _row(name, loss, f"{size}x{size}", [link_case(paths, party, link, imp, seed)])
            )
    return {
        "suite": suite,
        "pairs_from": f"{len(cases)} random pairs in +-99"
        if data is None
        else str(data) + ("" if pairs is None else f", its first {len(cases)} pairs"),
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


def format_link(result: dict[str, Any]) -> str:
    lines = [
        f"Link benchmark, suite {result['suite']}: medians per run; a "
        f"{result['rows'][0]['workload']} ({result['pairs_from']}) is one 1 x 1 comparison "
        "(keys included; the compact suite's one-time OT setup made before, as between drones "
        "that met; 'first contact': with a fresh OT setup), "
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
            f"| {duration_text(r['airtime_s'])} | {duration_text(r['wall_s_simulated'])} |"
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
