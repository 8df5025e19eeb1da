"""Re-run the benchmarks and rewrite their sections of docs/benchmarks.md.

Usage: .venv/bin/python scripts/record_benchmarks.py [crypto] [paper] [paper-dgk] [scaling]
[scaling-2000] [paper-separation] [scaling-separation] [design] [link] [replays] [replays-px4]
[fleet] [busy] [demo] (default: all; replays-px4 only
with PX4_SITL set to a PX4 SITL build) [--repeat N] [--data DIR]

``paper``, ``paper-dgk``, ``paper-separation`` and ``link`` run the paper's benchmark files,
read from ``--data DIR`` (default: ``../shared/anchor-data`` beside the repository); the
project does not carry them.

Each section sits between markers ``<!-- bench NAME -->`` and ``<!-- /bench NAME -->``; the
rest of the file is kept.  ``demo`` is README.md's: the summary ``make demo`` prints, so the
README's numbers are a run's, not typed in.  The new file is written next to the old one and
renamed over it, so an interrupted run leaves the old file intact.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

from companion.sim.bench_link import bench_link, format_link
from companion.sim.city import Band
from protocol.geo.volumes import Separation
from protocol.tools.bench import bench_crypto, format_crypto
from protocol.tools.bench_paths import (
    bench_design,
    bench_paper,
    bench_scaling,
    format_design,
    format_paper,
    format_scaling,
)

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "benchmarks.md"
README = ROOT / "README.md"
TARGETS = {"demo": README}  # sections kept in another file than DOC
SCENARIOS = ROOT / "sitl_configs" / "scenarios"
ANCHOR = ROOT.parent / "shared" / "anchor-data"  # the paper's files, where they are


def replays(px4: str | None = None, names: tuple[str, ...] = ()) -> str:
    """Every shipped scenario once (single runs): the replay report's figures; with ``px4``
    (a PX4 SITL build) the ``names`` scenarios on PX4 vehicles."""
    how = " --px4 DIR" if px4 else ""  # DIR: $PX4_SITL
    lines = [
        f"Replays: `python -m companion replay sitl_configs/scenarios/NAME.toml{how} --json`, "
        "one run each (single runs, not medians; simulated seconds).  Radio bytes: everything the "
        "companions sent (beacons, protocol messages, link headers, ACKs and retransmissions), "
        "all drones together.  First result: when the first run gave an Alice her answer "
        "(simulated seconds from the start); closest approach of each conflicting pair without "
        "and with the companion (t: when, with it).  Authentication: the bytes it added to the "
        "runs (key exchange, tags) and to the beacons (beyond unauthenticated 24-byte beacons: "
        "tags, signed and certificate beacons), and their share of the rest of the radio bytes.  "
        "Against deviating peers: the bytes of the OT consistency checks (or the paper suite's "
        "key proofs) in the answers, and their share of the rest.  These run in real time at "
        "each scenario's time scale (12-50x; MAVSDK and the mock autopilots over UDP): a "
        "protocol step's CPU then passes as that many times its seconds of flight -- a "
        "companion computer 12-50 times slower than this machine -- so runs end later than in "
        "virtual time (`--virtual`, what the tests fly: CPU counted 1:1), and a precaution "
        "the virtual replays never need can appear here.",
        "",
        "| scenario | link | conflicts resolved | precautionary | radio bytes | authentication "
        "| against deviating peers | airtime | first result | closest without -> with |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    paths = [SCENARIOS / f"{n}.toml" for n in names] or sorted(
        p
        for p in SCENARIOS.glob("*.toml")
        if p.stem not in BUSY  # (those: ``busy``)
    )
    for path in paths:
        print(f"  ... replay {path.stem}{how}", file=sys.stderr, flush=True)
        extra = ["--px4", px4] if px4 else []
        run = subprocess.run(  # noqa: S603 -- our own interpreter and scenario files
            [sys.executable, "-m", "companion", "replay", str(path), "--json", *extra],
            capture_output=True,
            text=True,
            check=False,
        )
        if run.returncode not in (0, 1):
            lines.append(f"| {path.stem} | failed: {run.stderr.strip()[-200:]} |")
            continue
        r = json.loads(run.stdout)
        results = [e["t_s"] for d in r["drones"] for e in d["timeline"] if e["kind"] == "result"]
        meets = [
            f"{p['closest_approach_baseline_m']:.1f} -> {p['closest_approach_m']:.1f} m"
            + (f" (t = {p['closest_approach_t_s']:.0f} s)" if p.get("closest_approach_t_s") else "")
            for p in r["pairs"]
            if p["conflict"] and p.get("trusted", True)
        ]
        link = r["link"]
        total = sum(d["bytes_sent"] for d in r["drones"])
        auth = sum(d["auth"]["run_bytes"] + d["auth"]["beacon_added_bytes"] for d in r["drones"])
        guard = sum(d.get("guard_bytes", 0) for d in r["drones"])
        lines.append(
            f"| {r['scenario']} | {link['profile']}, {link['loss']:.0%} loss "
            f"| {r['conflicts_resolved']}/{r['conflicts']} | {r['precautionary_actions']} "
            f"| {total} | {auth} (+{auth / (total - auth):.1%}) "
            f"| {guard} (+{guard / (total - guard):.1%}) "
            f"| {sum(d['airtime_s'] for d in r['drones']):.1f} s "
            f"| {f'{min(results):.0f} s' if results else '-'} "
            f"| {'; '.join(meets) or '-'} |"
        )
    return "\n".join(lines)


def demo() -> str:
    """What ``make demo`` prints: the crossing replay's text summary (one run)."""
    print("  ... replay crossing (the demo)", file=sys.stderr, flush=True)
    run = subprocess.run(  # noqa: S603 -- our own interpreter and scenario file
        [sys.executable, "-m", "companion", "replay", str(SCENARIOS / "crossing.toml")],
        capture_output=True,
        text=True,
        check=False,
    )
    if run.returncode not in (0, 1):
        raise SystemExit(f"the demo failed: {run.stderr.strip()[-500:]}")
    head = "One run (recorded by `scripts/record_benchmarks.py demo`):"
    return f"{head}\n\n```\n{run.stdout.strip()}\n```"


def fleet() -> str:
    """The fleet simulation (issue 29): a city's hour at 50 and 100 drones, one run each."""
    import time

    from companion.sim.city import CitySpec, run_city

    rows = [
        "| drones | hours | drone-h airborne | all flown | runs / drone-h | KB sent / drone-h "
        "| precautions / drone-h | conflicts | resolved | false alarms | made worse | wall s |",
        "|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    tables = []
    for drones in (50, 100):
        spec = CitySpec(drones=drones, hours=1.0)
        print(f"  ... fleet {drones} drones", file=sys.stderr, flush=True)
        start = time.perf_counter()
        city = run_city(spec)
        wall = time.perf_counter() - start
        r, hours = city.replay, city.drone_hours or float("inf")
        rows.append(
            f"| {drones} | 1 | {city.drone_hours:.1f} | {'yes' if r.finished else 'no'} "
            f"| {city.runs / hours:.1f} | {city.bytes_sent / 1000 / hours:.0f} "
            f"| {city.precautions / hours:.2f} "
            f"| {r.conflicts} | {r.conflicts_resolved} | {r.false_alarms} | {r.made_worse} "
            f"| {wall:.0f} |"
        )
        head = (
            f"{drones} drones -- drones in range (mean number of other airborne drones within "
            "radio range while airborne) against outcomes:"
        )
        tables.append(head + "\n\n" + _bands(city.bands))
    intro = (
        "`python -m companion fleet --drones N --hours 1` (6 km x 6 km, radio range 3 km, "
        "us915-sf7 at 10 % loss, seed 1), one run each (single runs, not medians); wall: "
        "this machine's seconds for the whole simulation and its report."
    )
    return intro + "\n\n" + "\n".join(rows) + "\n\n" + "\n\n".join(tables)


def _bands(bands: list[Band]) -> str:
    lines = [
        "| in range | drones | drone-h | runs / h | KB / h | channel load | precautions / h "
        "| conflicts | resolved | false alarms |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for b in bands:
        lines.append(
            f"| {b.span} | {b.drones} | {b.drone_hours:.2f} | {b.runs:.1f} | {b.kbytes:.0f} "
            f"| {b.load:.2f} | {b.precautions:.2f} | {b.conflicts} | {b.resolved} "
            f"| {b.false_alarms} |"
        )
    return "\n".join(lines)


BUSY = ("busy_six", "busy_ten", "busy_four_eu868")
EDIT_FAILED = ("plan_failed", "upload_failed")  # (a failed run is not a failed edit)


BUSY_RUNS = 8  # replays of each busy-sky scenario (single runs vary a lot; 10-40 s each)


def busy() -> str:
    """The busy-sky scenarios (issue 29) in virtual time, BUSY_RUNS runs each."""
    from companion.sim.replay import run_virtual
    from companion.sim.report import levels_up
    from companion.sim.scenario import load_scenario

    lines = [
        f"`python -m companion replay sitl_configs/scenarios/NAME.toml --virtual`, {BUSY_RUNS} "
        "runs each: the median, and the range in brackets.  Levels up: the most offsets any "
        "drone flew above its plan; failed: edits (or segments of one) that could not be "
        "planned or uploaded -- here all for want of an altitude under the 120 m ceiling; "
        "refused: requests refused BUSY (each after a whole request on the air).",
        "",
        "| scenario | link | conflicts resolved | precautions | false alarms | made worse "
        "| levels up (max) | failed edits | refused BUSY | KB sent per drone (max) "
        "| all missions flown |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for name in BUSY:
        rows: list[tuple[float, ...]] = []
        conflicts, flown = 0, True
        for i in range(BUSY_RUNS):
            print(f"  ... replay {name} --virtual ({i + 1})", file=sys.stderr, flush=True)
            r = run_virtual(load_scenario(SCENARIOS / f"{name}.toml")).report
            events = [e for d in r.drones for e in d.timeline]
            rows.append(
                (
                    r.conflicts_resolved,
                    r.precautionary_actions,
                    r.false_alarms,
                    r.made_worse,
                    max(levels_up(d, r.offset_m) for d in r.drones),
                    sum(f["kind"] in EDIT_FAILED for d in r.drones for f in d.failures),
                    sum(e["kind"] == "peer_busy" for e in events),
                    max(d.bytes_sent for d in r.drones) / 1000,
                )
            )
            conflicts, flown = r.conflicts, flown and r.finished
            link = f"{r.link.profile}, {r.link.loss:.0%} loss"
        cells = [_spread([row[k] for row in rows]) for k in range(len(rows[0]))]
        cells[0] = f"{cells[0]} of {conflicts}"
        lines.append(
            f"| {name} | {link} | " + " | ".join(cells) + f" | {'yes' if flown else 'no'} |"
        )
    return "\n".join(lines)


def _spread(values: list[float]) -> str:
    """'median (min-max)', integers where they are."""

    def fmt(v: float) -> str:
        return f"{v:.0f}" if float(v).is_integer() else f"{v:.1f}"

    low, high = min(values), max(values)
    middle = statistics.median(values)
    return fmt(middle) if low == high else f"{fmt(middle)} ({fmt(low)}-{fmt(high)})"


def sections(repeat: int, data: Path) -> dict[str, Callable[[], str]]:
    return {
        "crypto": lambda: format_crypto(bench_crypto(repeat=repeat)),
        "paper": lambda: format_paper(bench_paper(data, suite="compact")),
        "paper-dgk": lambda: format_paper(bench_paper(data, suite="paper")),
        "scaling": lambda: format_scaling(bench_scaling()),
        "scaling-2000": lambda: format_scaling(bench_scaling((8, 16), range_=2000)),
        # protected volumes (issue 26's targets): a separation of 30 grid units
        "paper-separation": lambda: format_paper(
            bench_paper(data, suite="compact", separation=Separation(30))
        ),
        "scaling-separation": lambda: format_scaling(
            bench_scaling((1, 2, 4, 8), range_=2000, separation=Separation(30))
        ),
        "design": lambda: format_design(bench_design()),
        "link": lambda: format_link(bench_link(data)),
        "replays": replays,
        # PX4 SITL (needs PX4_SITL=build): the crossing and the in-flight crossing
        "replays-px4": lambda: replays(
            os.environ.get("PX4_SITL", ""), ("crossing", "inflight_crossing")
        ),
        "fleet": fleet,
        "busy": busy,
        "demo": demo,
    }


def replace_section(text: str, name: str, body: str) -> str:
    start, end = f"<!-- bench {name} -->", f"<!-- /bench {name} -->"
    if start not in text or end not in text:
        return text.rstrip("\n") + f"\n\n{start}\n{body}\n{end}\n"
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{start}\n{body}\n{end}{tail}"


def main() -> int:
    table = sections(15, ANCHOR)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"sections: {', '.join(table)} (default all)")
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--data", type=Path, default=ANCHOR, help="the paper's benchmark files")
    args = parser.parse_args()
    unknown = set(args.names) - set(table)
    if unknown:
        parser.error(f"unknown sections: {', '.join(sorted(unknown))}")
    needs_data = {"paper", "paper-dgk", "link"} & set(args.names or table)
    if needs_data and not (args.data / "alices_segments.txt").is_file():
        parser.error(f"{', '.join(sorted(needs_data))}: no paper's files in {args.data} (--data)")
    table = sections(args.repeat, args.data)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    default = [n for n in table if n != "replays-px4" or os.environ.get("PX4_SITL")]
    if "replays-px4" in args.names and not os.environ.get("PX4_SITL"):
        parser.error("replays-px4 needs PX4_SITL=path of a PX4 SITL build")
    for name in args.names or default:
        doc = TARGETS.get(name, DOC)
        body = f"Machine: {machine}.\n\n{table[name]()}"
        print(body, flush=True)
        # read after the (minutes of) measuring: another recorder may have written meanwhile
        text = doc.read_text() if doc.exists() else "# Benchmarks\n"
        text = replace_section(text, name, body)
        tmp = doc.with_suffix(".md.tmp")
        tmp.write_text(text)
        tmp.replace(doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
