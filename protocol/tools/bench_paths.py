"""Benchmarks of the path protocol: ``bench paper`` and ``bench scaling``.

Each run goes through :func:`protocol.loopback.run_paths`: bytes are the serialised frames
(public keys and setup ids included, they travel in messages 1 and 2), CPU is
``time.process_time`` of each party's steps.  What two drones do once (the compact suite's OT
setup, the paper suite's key generation) is reported on its own line, with its bytes.
"""

from __future__ import annotations

import dataclasses
import secrets
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from protocol.geo.geometry import Point
from protocol.geo.grid import GridKind, GridSpec
from protocol.geo.volumes import NO_SEPARATION, Separation, VolumeSpec
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.ot import check
from protocol.ot.setup import DEFAULT_SECURITY
from protocol.paper import keyproof
from protocol.tools.compare import Case, Party, describe_once, params_of, run_case
from protocol.tools.loopback import run_paths
from protocol.tools.paper_data import load_paper_data

# Quoted, not measured here: the paper's published figures, and its code as the project's
# field notes measured it.
PAPER_PUBLISHED = {"time_s": 4.407, "bytes": 4634, "note": "bytes are JVM object sizes"}
PAPER_CODE_QUOTED = {
    "time_s": 4.1,
    "cpu_s": 1.6,
    "bytes": 86_800,
    "key_bytes": 20_200_000,
    "security_bits": 80,
}


class CheckCost:
    """The CPU malicious security takes in the runs made while it is active: the OT
    consistency check (Bob's reply, Alice's check) and Alice's check of Bob's Paillier key
    proof -- the real calls of the run, timed.  A tool's instrument: it wraps
    :mod:`protocol.ot.check` and :func:`protocol.paper.keyproof.verify` for the duration."""

    # (module, function, whose CPU it is)
    TIMED = ((check, "respond", "bob"), (check, "verify", "alice"), (keyproof, "verify", "alice"))

    def __enter__(self) -> CheckCost:
        self.spent = {"alice": 0.0, "bob": 0.0}
        self._saved = [getattr(module, name) for module, name, _ in self.TIMED]
        for (module, name, party), real in zip(self.TIMED, self._saved, strict=True):
            setattr(module, name, self._timed(real, party))
        return self

    def _timed(self, real: Any, party: str) -> Any:
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            try:
                return real(*args, **kwargs)
            finally:
                self.spent[party] += time.process_time() - start

        return timed

    def __exit__(self, *exc: object) -> None:
        for (module, name, _), real in zip(self.TIMED, self._saved, strict=True):
            setattr(module, name, real)


def _run(case: Case, party: Party) -> dict[str, Any]:
    """One case through the loopback (:func:`run_case`), with the CPU its protection against
    a deviating Bob took (:class:`CheckCost`; the bytes are ``run_case``'s ``guard_bytes``)."""
    with CheckCost() as cost:
        result = run_case(case, party)
    result["guard_cpu_s_alice"] = cost.spent["alice"]
    result["guard_cpu_s_bob"] = cost.spent["bob"]
    return result


def _say(progress: bool, message: str) -> None:
    if progress:
        print(f"  ... {message}", file=sys.stderr, flush=True)


def _summary(results: list[dict[str, Any]], pairs: list[int]) -> dict[str, Any]:
    per_pair = [
        (
            r["cpu_s_alice"] / p,
            r["cpu_s_bob"] / p,
            r["bytes_alice_to_bob"] / p,
            r["bytes_bob_to_alice"] / p,
        )
        for r, p in zip(results, pairs, strict=True)
    ]
    a, b, ab, ba = (statistics.median(col) for col in zip(*per_pair, strict=True))
    return {
        "runs": len(results),
        "correct": sum(r["hits"] == r["plain_hits"] for r in results),
        "median_cpu_s_alice": a,
        "median_cpu_s_bob": b,
        "median_cpu_s_total": statistics.median(x + y for x, y, _, _ in per_pair),
        "median_bytes_alice_to_bob": ab,
        "median_bytes_bob_to_alice": ba,
        "median_bytes_total": statistics.median(x + y for _, _, x, y in per_pair),
        "messages": max(r["messages"] for r in results),
        "median_guard_bytes": statistics.median(r["guard_bytes"] for r in results),
        "median_guard_cpu_s": statistics.median(
            r["guard_cpu_s_alice"] + r["guard_cpu_s_bob"] for r in results
        ),
    }


def bench_paper(
    data: Path,
    suite: str = "compact",
    progress: bool = True,
    separation: Separation = NO_SEPARATION,
) -> dict[str, Any]:
    """The paper's 30 single-segment pairs and its 5 route tests, from the directory ``data``
    (:mod:`.paper_data`), with ``separation`` (none: the paper's crossing test)."""
    paper = load_paper_data(data, separation)
    _say(progress, f"generating keys ({suite})")
    party = Party.generate(Suite.COMPACT if suite == "compact" else Suite.PAPER)
    cases = paper.pairs
    pair_results, first_results = [], []
    for number, case in enumerate(cases, start=1):
        _say(progress, f"pair {number}/{len(cases)}")
        pair_results.append(_run(case, party))
        if party.setup is not None:  # and as the first contact of two drones: a fresh setup
            first_results.append(_run(case, dataclasses.replace(party, setup=None, setups={})))
    routes = []
    for route in paper.routes:
        _say(progress, f"route {route.number}")
        result = _run(route.case, party)
        result["route"] = route.number
        result["segments"] = (route.case.alice.segments, route.case.bob.segments)
        result["hit_indices"] = [i for i, h in enumerate(result["hits"]) if h]
        result["expected_any"] = route.expected_any
        routes.append(result)
    span = paper.routes[0].case.grid.range if paper.routes else 1
    return {
        "suite": suite,
        "separation": separation.horizontal,
        "data": str(paper.directory),
        "params": params_of(party, cases[0].grid),
        "route_grid_range": span,
        "route_comparison_bits": GridSpec(GridKind.PLANE, span).l,
        "pairs": _summary(pair_results, [1] * len(pair_results)),
        "first_contact": _summary(first_results, [1] * len(first_results))
        if first_results
        else None,
        "routes": routes,
        "paper_published_quoted": PAPER_PUBLISHED,
        "paper_code_quoted": PAPER_CODE_QUOTED,  # from the field notes, not measured here
    }


def _separation(result: dict[str, Any]) -> str:
    r = result.get("separation", 0)
    return f"separation {r} grid units" if r else "the crossing test"


def _over(added: float, total: float) -> str:
    """``added`` bytes as a share of the run without them."""
    return f"{100 * added / (total - added):.1f} %"


def format_paper(result: dict[str, Any]) -> str:
    p, s, f = result["params"], result["pairs"], result.get("first_contact")
    total = s["median_bytes_total"]
    what = (
        "the OT consistency check"
        if f is not None
        else "Bob's Paillier key proof; Alice checks it once per key, later runs hit her cache"
    )
    total_note = " (keys included)" if f is None else " (OT setup cached)"
    first_rows = (
        []
        if f is None
        else [
            f"| first contact (fresh OT setup), median bytes per pair | "
            f"{f['median_bytes_total']:.0f} | - | - |",
            f"| first contact (fresh OT setup), median CPU per pair, both | "
            f"{f['median_cpu_s_total'] * 1e3:.1f} ms | - | - |",
        ]
    )
    lines = [
        f"Paper benchmark, suite {result['suite']} ({p['scheme']}), {_separation(result)}, l = "
        f"{p['comparison_bits']} bits (range +-{p['grid_range']}); once per pair of drones: "
        f"{describe_once(p)}.",
        "",
        f"| {s['runs']} single-segment pairs | this project | paper's code (quoted: field notes) "
        "| paper, published (quoted) |",
        "|---|---:|---:|---:|",
        f"| correct | {s['correct']}/{s['runs']} | 30/30 | - |",
        f"| median CPU per pair, Alice | {s['median_cpu_s_alice'] * 1e3:.1f} ms | - | - |",
        f"| median CPU per pair, Bob | {s['median_cpu_s_bob'] * 1e3:.1f} ms | - | - |",
        f"| median CPU per pair, both | {s['median_cpu_s_total'] * 1e3:.1f} ms "
        f"| {PAPER_CODE_QUOTED['cpu_s'] * 1e3:.0f} ms CPU, "
        f"{PAPER_CODE_QUOTED['time_s']:.1f} s wall "
        f"| {PAPER_PUBLISHED['time_s']:.3f} s |",
        f"| median bytes per pair, A->B | {s['median_bytes_alice_to_bob']:.0f} | 40 400 | - |",
        f"| median bytes per pair, B->A | {s['median_bytes_bob_to_alice']:.0f} | 46 400 | - |",
        f"| median bytes per pair, total{total_note} | {s['median_bytes_total']:.0f} "
        f"| 86 800 + 20.2 MB key | 4634 (object sizes) |",
        *first_rows,
        f"| of which against a deviating peer ({what}), median bytes and CPU per pair "
        f"| {s['median_guard_bytes']:.0f} B (+{_over(s['median_guard_bytes'], total)} "
        f"on the run without it), {s['median_guard_cpu_s'] * 1e3:.1f} ms | - | - |",
        f"| messages | {s['messages']:.0f} | about 96 | - |",
        "| security | 112-bit, nothing leaked | 80-bit DGK, leaks every bit | - |",
        "",
        f"Routes (grid range +-{result['route_grid_range']}, "
        f"l = {result['route_comparison_bits']}; single run per route, not medians):",
        "",
        "| route | m x n | hit segments | plaintext | expected any (crossing) | bytes "
        "| Alice CPU s | Bob CPU s |",
        "|---:|---|---|---|---|---:|---:|---:|",
    ]
    for r in result["routes"]:
        plain = [i for i, h in enumerate(r["plain_hits"]) if h]
        lines.append(
            f"| {r['route']} | {r['segments'][0]} x {r['segments'][1]} | {r['hit_indices']} "
            f"| {plain} | {r['expected_any']} "
            f"| {r['bytes_alice_to_bob'] + r['bytes_bob_to_alice']} "
            f"| {r['cpu_s_alice']:.3f} | {r['cpu_s_bob']:.3f} |"
        )
    return "\n".join(lines)


def random_path(segments: int, range_: int) -> tuple[Point, ...]:
    return tuple(
        (secrets.randbelow(2 * range_ + 1) - range_, secrets.randbelow(2 * range_ + 1) - range_)
        for _ in range(segments + 1)
    )


def random_pairs(count: int = 30, range_: int = 99) -> list[Case]:
    """``count`` random single-segment pairs in +-``range_``: the shape of the paper's
    benchmark pairs, for a benchmark run without the paper's files."""
    grid = GridSpec(GridKind.PLANE, range_)
    return [Case.of(random_path(1, range_), random_path(1, range_), grid) for _ in range(count)]


def bench_scaling(
    sizes: tuple[int, ...] = (1, 2, 4, 8, 16, 32),
    suite: str = "compact",
    range_: int = 99,
    progress: bool = True,
    repeat: int = 3,
    separation: Separation = NO_SEPARATION,
) -> dict[str, Any]:
    """Random paths with n = m segments, coordinates in [-range, range]: ``repeat`` cases per
    size (bytes depend on the sizes alone; CPU as medians); with ``separation`` the grid
    leaves room for it around the paths."""
    _say(progress, f"generating keys ({suite})")
    party = Party.generate(Suite.COMPACT if suite == "compact" else Suite.PAPER)
    room = separation.horizontal + 1 if separation.horizontal else 0
    grid = GridSpec(GridKind.PLANE, range_ + room)
    volumes = VolumeSpec(separation)
    once = party.once
    setup_bytes = int(
        once.get("setup_bytes_alice_to_bob", 0) + once.get("setup_bytes_bob_to_alice", 0)
    )
    rows = []
    for size in sizes:
        results = []
        for k in range(repeat):
            _say(progress, f"{size} x {size} ({k + 1}/{repeat})")
            case = Case.of(
                random_path(size, range_), random_path(size, range_), grid, volumes=volumes
            )
            results.append(_run(case, party))
        r = results[-1]
        pairs = size * size
        total = r["bytes_alice_to_bob"] + r["bytes_bob_to_alice"]
        rows.append(
            {
                "segments": size,
                "pairs": pairs,
                "runs": repeat,
                "correct": sum(x["hits"] == x["plain_hits"] for x in results),
                "bytes_total": total,
                "bytes_per_pair": total / pairs,
                "bytes_first_contact": total + setup_bytes,
                "bytes_alice_to_bob": r["bytes_alice_to_bob"],
                "bytes_bob_to_alice": r["bytes_bob_to_alice"],
                "messages": r["messages"],
                "cpu_s_alice": statistics.median(x["cpu_s_alice"] for x in results),
                "cpu_s_bob": statistics.median(x["cpu_s_bob"] for x in results),
                "guard_bytes": r["guard_bytes"],
                "guard_cpu_s": statistics.median(
                    x["guard_cpu_s_alice"] + x["guard_cpu_s_bob"] for x in results
                ),
            }
        )
    return {
        "suite": suite,
        "separation": separation.horizontal,
        "params": params_of(party, grid),
        "rows": rows,
    }


def format_scaling(result: dict[str, Any]) -> str:
    p = result["params"]
    lines = [
        f"Scaling, suite {result['suite']} ({p['scheme']}), random paths in a grid of range "
        f"+-{p['grid_range']}, {_separation(result)}, l = {p['comparison_bits']} bits; once per "
        f"pair of drones: {describe_once(p)}.  Bytes are fixed by the sizes (padded); CPU is "
        "the median of the runs.",
        "",
        "| n = m | pairs | correct | total bytes | bytes per pair | first contact bytes "
        "| messages | Alice CPU s | Bob CPU s | against a deviating peer: bytes (share of the "
        "run without them), CPU ms |",
        "|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["rows"]:
        share = _over(r["guard_bytes"], r["bytes_total"])
        lines.append(
            f"| {r['segments']} | {r['pairs']} | {r['correct']}/{r['runs']} "
            f"| {r['bytes_total']} | {r['bytes_per_pair']:.0f} | {r['bytes_first_contact']} "
            f"| {r['messages']} | {r['cpu_s_alice']:.2f} | {r['cpu_s_bob']:.2f} "
            f"| {r['guard_bytes']} (+{share}), {r['guard_cpu_s'] * 1e3:.1f} |"
        )
    return "\n".join(lines)


def bench_design(size: int = 8, range_: int = 99, progress: bool = True) -> dict[str, Any]:
    """The design study behind the compact suite: one size x size case, every variant.

    Variants: the OT extension's block size (1 bit = IKNP's kappa bits per OT; SoftSpokenOT
    sends blocks - 1 bits per OT and does 2^k work per block; 12 = the default), its
    security parameter kappa (112 = the default, 128), the millionaires' digit size (4 = the
    default), and the paper suite on the same paths.  Real bytes and CPU of one run each;
    the one-time OT setup (made once per variant) in its own columns."""
    grid = GridSpec(GridKind.PLANE, range_)
    case = Case.of(random_path(size, range_), random_path(size, range_), grid)
    variants: list[tuple[str, int, int, int]] = [
        ("compact", 12, w, DEFAULT_SECURITY) for w in (2, 3, 4, 5, 6)
    ]
    variants += [("compact", k, 4, DEFAULT_SECURITY) for k in (1, 4, 8)]
    variants += [("compact", 12, 4, 128), ("paper", 0, 0, 0)]
    rows = []
    parties: dict[tuple[int, int], Party] = {}
    for suite, blocks, digits, security in variants:
        _say(progress, f"{suite} blocks={blocks} digits={digits} kappa={security}")
        if suite == "paper":
            party = Party.generate(Suite.PAPER)
            alice, bob = case.machines(party)
            setup_bytes = 0
        else:
            key = (blocks, security)
            party = parties.get(key) or Party.generate(
                Suite.COMPACT, block_bits=blocks, ot_security=security
            )
            parties[key] = party
            alice = Alice(case.alice, grid, setup=party.setup, digit_bits=digits)
            bob = Bob(case.bob, setups=party.setups)
            setup_bytes = int(
                party.once["setup_bytes_alice_to_bob"] + party.once["setup_bytes_bob_to_alice"]
            )
        t = run_paths(alice, bob)
        rows.append(
            {
                "suite": suite,
                "ot_block_bits": blocks,
                "ot_security": security,
                "digit_bits": digits,
                "correct": alice.hits == case.plain_hits(),
                "bytes_total": t.bytes_alice_to_bob + t.bytes_bob_to_alice,
                "setup_bytes": setup_bytes,
                "setup_cpu_s": sum(v for k, v in party.once.items() if "cpu" in k),
                "messages": t.messages,
                "cpu_s_alice": t.cpu_alice,
                "cpu_s_bob": t.cpu_bob,
                "sizes": t.sizes,
            }
        )
    return {"size": size, "grid_range": range_, "comparison_bits": grid.l, "rows": rows}


def format_design(result: dict[str, Any]) -> str:
    lines = [
        f"Design study: one {result['size']} x {result['size']} case, coordinates in "
        f"+-{result['grid_range']} (l = {result['comparison_bits']}); one run per row "
        "(single runs, not medians).  The OT setup is made once per pair of drones.",
        "",
        "| suite | OT block bits | kappa | digit bits | correct | run bytes | messages "
        "| Alice CPU s | Bob CPU s | setup bytes | setup CPU s |",
        "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["rows"]:
        paper = r["suite"] == "paper"
        blocks, kappa, digits = (
            ("-", "-", "-") if paper else (r["ot_block_bits"], r["ot_security"], r["digit_bits"])
        )
        setup = ("-", "-") if paper else (r["setup_bytes"], f"{r['setup_cpu_s']:.2f}")
        lines.append(
            f"| {r['suite']} | {blocks} | {kappa} | {digits} | {'yes' if r['correct'] else 'NO'} "
            f"| {r['bytes_total']} | {r['messages']} | {r['cpu_s_alice']:.2f} "
            f"| {r['cpu_s_bob']:.2f} | {setup[0]} | {setup[1]} |"
        )
    return "\n".join(lines)
