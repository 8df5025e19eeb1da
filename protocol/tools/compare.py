"""``python -m protocol compare ALICE BOB``: run both parties in one process, on real bytes.

The two drones' one-time material is made once per invocation and reported separately, as
drones do it once per peer: the compact suite's OT setup (its bytes and CPU), the paper
suite's keys.  Each case runs the whole protocol through :func:`protocol.loopback.run_paths`,
so the byte counts are the frames a radio would carry (keys and setup ids included) and the
CPU seconds are each party's own steps.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from protocol.geo.geometry import Point
from protocol.geo.grid import DEFAULT_RADIUS_M, DEFAULT_RESOLUTION_MM, GridKind, GridSpec
from protocol.geo.volumes import CROSSING, NO_SEPARATION, Route, Separation, VolumeSpec, route_hits
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.ot.setup import (
    DEFAULT_BLOCK_BITS,
    DEFAULT_SECURITY,
    ChooserSetup,
    HolderSetup,
    describe,
    split_blocks,
)
from protocol.paper.keys import BobKeys
from protocol.run import Limits
from protocol.tools.formats import InputFormatError, parse_paper_text, read_text, route_of
from protocol.tools.loopback import run_ot_setup, run_paths

SUITES = {"compact": Suite.COMPACT, "paper": Suite.PAPER}


@dataclass(frozen=True)
class Case:
    """One comparison.  With ``bob_geographic`` Bob's path is WGS84 (degE7) and Bob projects
    it himself on the grid Alice's hello announces, as a drone does.  ``volumes`` are Alice's
    (her separation, the altitude and time ranges), ``bob_separation`` Bob's own minima."""

    alice: Route
    bob: Route
    grid: GridSpec
    bob_geographic: bool = False
    volumes: VolumeSpec = CROSSING
    bob_separation: Separation = NO_SEPARATION

    @classmethod
    def of(cls, alice: Sequence[Point], bob: Sequence[Point], grid: GridSpec, **more: Any) -> Case:
        """A case of two plain paths (no bands, no windows)."""
        return cls(Route(tuple(alice)), Route(tuple(bob)), grid, **more)

    @property
    def bob_on_grid(self) -> Route:
        if not self.bob_geographic:
            return self.bob
        return dataclasses.replace(self.bob, points=self.grid.project_path(self.bob.points))

    def plain_hits(self) -> list[bool]:
        """The plaintext predicate on what the run compares (the larger separation, bands
        and windows clamped to the public ranges): what the answer must be."""
        run = dataclasses.replace(
            self.volumes, separation=self.volumes.separation.widest(self.bob_separation)
        )
        return route_hits(run.clamp(self.alice), run.clamp(self.bob_on_grid), run.separation)

    def machines(self, party: Party, limits: Limits | None = None) -> tuple[Alice, Bob]:
        limits = limits or Limits()
        return (
            Alice(
                self.alice,
                self.grid,
                suite=party.suite,
                setup=party.setup,
                limits=limits,
                volumes=self.volumes,
                trusted_keys=True,  # both parties are this process's
            ),
            Bob(
                self.bob,
                keys=party.bob_keys,
                setups=party.setups,
                geographic=self.bob_geographic,
                limits=limits,
                separation=self.bob_separation,
            ),
        )


GeoPath = tuple[tuple[int, int], ...]
# Reads a mission file into the ground path its autopilot flies (degE7); the companion's
# ``companion.mission.flightpath`` knows how (launch leg, loiters, DO_JUMP, RTL), this package does
# not.
MissionReader = Callable[[Path], GeoPath]


def grid_holds(lat: int, lon: int, radius_m: float, points: GeoPath) -> bool:
    """Does the grid of ``radius_m`` around (lat, lon) hold every point?"""
    grid = GridSpec.geo(lat, lon, radius_m=radius_m)
    return all(max(map(abs, grid.project(*p, checked=False))) <= grid.range for p in points)


def is_mission_file(path: str | Path, text: str) -> bool:
    """A QGroundControl ``.plan`` (JSON) or ``QGC WPL`` file rather than the paper's format."""
    head = text.lstrip()
    return str(path).endswith((".plan", ".waypoints")) or head.startswith(("{", "QGC WPL"))


def load_cases(
    alice_file: str | Path,
    bob_file: str | Path,
    *,
    range_: int | None = None,
    resolution_mm: int = DEFAULT_RESOLUTION_MM,
    radius_m: float = DEFAULT_RADIUS_M,
    read_mission: MissionReader | None = None,
    separation: Separation = NO_SEPARATION,
    time_tolerance: int = 0,
) -> list[Case]:
    """Pair line k of ALICE with line k of BOB (paper format) or two mission files (one
    case, their flown paths as ``read_mission`` gives them; the grid is centred on Alice's
    first point and wide enough for both paths).  Both parties use ``separation``; vertices
    with altitudes (times) make the runs compare bands (windows, each widened by
    ``time_tolerance`` seconds), the ranges the files' extent."""
    a_text, b_text = read_text(alice_file), read_text(bob_file)
    a_plan, b_plan = is_mission_file(alice_file, a_text), is_mission_file(bob_file, b_text)
    if a_plan != b_plan:
        raise InputFormatError("both files must be missions, or both in the paper's format")
    if a_plan:
        return _mission_cases(alice_file, bob_file, range_, resolution_mm, radius_m, read_mission)
    a_lines = parse_paper_text(a_text, str(alice_file))
    b_lines = parse_paper_text(b_text, str(bob_file))
    if len(a_lines) != len(b_lines):
        raise InputFormatError(
            f"{alice_file} has {len(a_lines)} paths but {bob_file} has {len(b_lines)}"
        )
    pairs = [
        (route_of(a, time_tolerance), route_of(b, time_tolerance))
        for a, b in zip(a_lines, b_lines, strict=True)
    ]
    r = separation.horizontal
    if range_ is None:
        # The range is public: both operators agree on it.  Here: the files' extent, and room
        # for the separation around Alice's path (Bob's is cut to the box).
        range_ = max(
            max(abs(c) for p in a.points + b.points for c in p) + (r + 1 if r else 0)
            for a, b in pairs
        )
    grid = GridSpec(GridKind.PLANE, max(1, range_))
    for a, b in pairs:
        grid.check_points(a.points)
        grid.check_points(b.points)
    volumes = _volumes_of(pairs, separation)
    return [Case(a, b, grid, volumes=volumes, bob_separation=separation) for a, b in pairs]


def _mission_cases(
    alice_file: str | Path,
    bob_file: str | Path,
    range_: int | None,
    resolution_mm: int,
    radius_m: float,
    read_mission: MissionReader | None,
) -> list[Case]:
    """:func:`load_cases` of two mission files: one case, on a grid centred on Alice's first
    point (``range_``, or doubling ``radius_m`` until it holds both paths)."""
    if read_mission is None:
        raise InputFormatError(
            f"{alice_file}: mission files are compared as the autopilot flies them by "
            "`python -m companion compare` (this command reads the paper's format)"
        )
    a_geo, b_geo = read_mission(Path(alice_file)), read_mission(Path(bob_file))
    for path, geo in ((alice_file, a_geo), (bob_file, b_geo)):
        if len(geo) < 2:
            raise InputFormatError(f"{path}: the mission flies no segment")
    lat, lon = a_geo[0]
    if range_ is not None:
        grid = GridSpec(GridKind.GEO, range_, lat, lon, resolution_mm)
    else:
        radius = radius_m
        while not grid_holds(lat, lon, radius, a_geo + b_geo):
            radius *= 2
        grid = GridSpec.geo(lat, lon, resolution_mm=resolution_mm, radius_m=radius)
    return [Case.of(grid.project_path(a_geo), b_geo, grid, bob_geographic=True)]


def _volumes_of(pairs: Sequence[tuple[Route, Route]], separation: Separation) -> VolumeSpec:
    """The runs' volumes: ``separation``, and altitude and time ranges the routes' extent."""
    bands = [x for a, b in pairs for route in (a, b) for x in route.bands or ()]
    windows = [x for a, b in pairs for route in (a, b) for x in route.windows or ()]
    return VolumeSpec(
        separation,
        z_range=max((max(abs(lo), abs(hi)) for lo, hi in bands), default=0) or int(bool(bands)),
        t_range=max((hi for _, hi in windows), default=0) or int(bool(windows)),
    )


@dataclass
class Party:
    """What two drones keep between runs: the OT setup (compact) or Bob's keys (paper)."""

    suite: Suite
    bob_keys: BobKeys | None
    setup: HolderSetup | None
    setups: dict[bytes, ChooserSetup]
    once: dict[str, float]  # one-time costs: CPU seconds and bytes

    @classmethod
    def generate(
        cls,
        suite: Suite,
        *,
        block_bits: int = DEFAULT_BLOCK_BITS,
        ot_security: int = DEFAULT_SECURITY,
    ) -> Party:
        if suite is Suite.PAPER:
            start = time.process_time()
            keys = BobKeys.generate()
            return cls(suite, keys, None, {}, {"bob_keygen_s": time.process_time() - start})
        chooser, setup, t = run_ot_setup(split_blocks(block_bits, ot_security))
        once = {
            "setup_cpu_s_alice": t.cpu_alice,
            "setup_cpu_s_bob": t.cpu_bob,
            "setup_bytes_alice_to_bob": t.bytes_alice_to_bob,
            "setup_bytes_bob_to_alice": t.bytes_bob_to_alice,
        }
        return cls(suite, None, setup, {chooser.setup_id: chooser}, once)


def run_case(case: Case, party: Party, limits: Limits | None = None) -> dict[str, Any]:
    alice, bob = case.machines(party, limits)
    t = run_paths(alice, bob)
    return {
        "guard_bytes": alice.guard_bytes,
        "hits": alice.hits,
        "plain_hits": case.plain_hits(),
        "bytes_alice_to_bob": t.bytes_alice_to_bob,
        "bytes_bob_to_alice": t.bytes_bob_to_alice,
        "messages": t.messages,
        "round_trips": t.round_trips,
        "cpu_s_alice": t.cpu_alice,
        "cpu_s_bob": t.cpu_bob,
        "message_sizes": [[name, size] for name, size in t.sizes],
    }


def params_of(party: Party, grid: GridSpec, kappa: int = 40) -> dict[str, Any]:
    common = {
        "grid_kind": grid.kind.name.lower(),
        "grid_range": grid.range,
        "resolution_mm": grid.resolution_mm,
        "comparison_bits": grid.l,
        "once": party.once,
    }
    if party.bob_keys is not None:
        return {
            "scheme": "Paillier-2048 + DGK-2048 (t = 224)",
            "paillier_bits": int(party.bob_keys.paillier.public_key.n.bit_length()),
            "kappa": kappa,
            **common,
        }
    assert party.setup is not None
    return {"scheme": f"OT extension ({describe(party.setup.blocks)})", **common}


def compare(
    alice_file: str | Path,
    bob_file: str | Path,
    suite_name: str = "compact",
    *,
    range_: int | None = None,
    progress: bool = False,
    run: Callable[[Case, Party], dict[str, Any]] = run_case,
    read_mission: MissionReader | None = None,
    separation: Separation = NO_SEPARATION,
    time_tolerance: int = 0,
) -> dict[str, Any]:
    """Everything ``compare --json`` prints; ``run`` carries one case (in memory by default,
    the companion passes one that goes through the simulated radio)."""
    cases = load_cases(
        alice_file,
        bob_file,
        range_=range_,
        read_mission=read_mission,
        separation=separation,
        time_tolerance=time_tolerance,
    )
    party = Party.generate(SUITES[suite_name])
    results = []
    for number, case in enumerate(cases, start=1):
        if progress:
            print(f"  ... case {number}/{len(cases)}", flush=True, file=sys.stderr)
        results.append(run(case, party))
    volumes = cases[0].volumes
    return {
        "suite": suite_name,
        "params": params_of(party, cases[0].grid),
        "volumes": {
            "separation": volumes.separation.horizontal,
            "vertical_separation": volumes.separation.vertical,
            "altitude_range": volumes.z_range,
            "time_range_s": volumes.t_range,
        },
        "cases": results,
    }


def describe_once(params: dict[str, Any]) -> str:
    once = params["once"]
    if "bob_keygen_s" in once:
        return f"Bob's keys, {1e3 * once['bob_keygen_s']:.0f} ms CPU"
    size = once["setup_bytes_alice_to_bob"] + once["setup_bytes_bob_to_alice"]
    cpu = once["setup_cpu_s_alice"] + once["setup_cpu_s_bob"]
    return f"OT setup, {size} B on the radio and {1e3 * cpu:.0f} ms CPU (not in the per-run rows)"


def format_compare(result: dict[str, Any]) -> str:
    p = result["params"]
    v = result.get("volumes", {})
    volumes = (
        f"; separation {v['separation']}, vertical {v['vertical_separation']} (grid units)"
        + (", altitudes" if v["altitude_range"] else "")
        + (", times" if v["time_range_s"] else "")
        if v and (v["separation"] or v["altitude_range"] or v["time_range_s"])
        else "; the crossing test"
    )
    lines = [
        f"suite {result['suite']} ({p['scheme']}), grid range +-{p['grid_range']} "
        f"-> l = {p['comparison_bits']} bits{volumes}; once per pair of drones: "
        f"{describe_once(p)}",
        "",
        "| case | hits (Alice's segments) | plaintext | A->B bytes | B->A bytes | msgs "
        "| round trips | Alice CPU s | Bob CPU s |",
        "|---:|---|---|---:|---:|---:|---:|---:|---:|",
    ]

    def bits(values: Sequence[bool]) -> str:
        return "".join("1" if v else "0" for v in values)

    for number, c in enumerate(result["cases"], start=1):
        lines.append(
            f"| {number} | {bits(c['hits'])} | {bits(c['plain_hits'])} "
            f"| {c['bytes_alice_to_bob']} | {c['bytes_bob_to_alice']} | {c['messages']} "
            f"| {c['round_trips']} | {c['cpu_s_alice']:.3f} | {c['cpu_s_bob']:.3f} |"
        )
    if "link" in result:
        link = result["link"]
        lines += [
            "",
            f"link {link['profile']} ({link['frame_bytes']}-byte frames), loss {link['loss']:.0%}, "
            f"corruption {link['corrupt']:.0%}, seed {link['seed']}",
            "",
            "| case | frames | retransmitted | bytes on air | airtime s | simulated s |",
            "|---:|---:|---:|---:|---:|---:|",
        ]
        for number, c in enumerate(result["cases"], start=1):
            lines.append(
                f"| {number} | {c['frames_sent']} | {c['frames_retransmitted']} "
                f"| {c['bytes_on_air']} | {c['airtime_s']:.1f} | {c['wall_s_simulated']:.1f} |"
            )
    agree = sum(c["hits"] == c["plain_hits"] for c in result["cases"])
    lines += ["", f"{agree}/{len(result['cases'])} cases agree with the plaintext predicate."]
    return "\n".join(lines)
