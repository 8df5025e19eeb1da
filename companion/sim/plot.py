"""The encounter as a figure: ground tracks, the distance of each pair, altitudes."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from companion.sim.metrics import closest, enu, separation
from companion.sim.replay import Replay, Tracks
from companion.sim.report import FEW, NEAR_FACTOR, ReplayReport, shown_pairs
from companion.sim.scenario import ScenarioError
from companion.sim.vehicles import Track

MARKERS = {
    "run_started": ("^", "run started"),
    "result": ("o", "result"),
    "uploaded": ("*", "edit verified"),
    "precautionary": ("X", "precaution"),
}


PLOT_FORMATS = ("png", "pdf", "svg")


def plot_report(replay: Replay, out: str | Path) -> None:
    """PNG, PDF or SVG (by ``out``'s ending): ground tracks (planned, flown, direction,
    closest approaches), the distance of every pair over time with the runs' moments marked,
    and altitudes over the flight window.  With more than a few drones only the pairs that
    came near are drawn and the legends go below the panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    kind = out.suffix.lower().lstrip(".")
    if kind not in PLOT_FORMATS:
        raise ScenarioError(f"{out}: a plot is {', '.join(PLOT_FORMATS)} (by the file's ending)")
    report, tracks = replay.report, replay.tracks
    ref = next(iter(tracks.paths.values()))[0]
    ref_deg = (ref[0] / 1e7, ref[1] / 1e7)

    def en(lat: float, lon: float) -> tuple[float, float]:
        north, east, _ = enu((lat, lon, 0.0), ref_deg)
        return east, north

    many = len(report.drones) > FEW  # legends below the panels, not over them
    fig, (ground, gap, height) = plt.subplots(1, 3, figsize=(24 if many else 19, 6))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {d.id: colours[n % len(colours)] for n, d in enumerate(report.drones)}
    _ground(ground, report, tracks, colour, en)
    _gaps(gap, report, tracks, colour)
    _heights(height, report, tracks, colour)
    for panel in (ground, gap, height):
        _legend(panel, outside=many)
    fig.tight_layout()
    tmp = out.with_name(f".{out.name}.tmp")
    try:
        fig.savefig(tmp, dpi=100, format=kind, bbox_inches="tight")
        tmp.replace(out)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)


def _ground(
    ground: Any,
    report: ReplayReport,
    tracks: Tracks,
    colour: dict[int, str],
    en: Callable[[float, float], tuple[float, float]],
) -> None:
    """Ground tracks: planned, flown with direction arrows, flagged segments, and each
    pair's closest approach."""
    for drone in report.drones:
        ident, c = drone.id, colour[drone.id]
        path = [en(lat / 1e7, lon / 1e7) for lat, lon in tracks.paths[ident]]
        ground.plot(*zip(*path, strict=True), "o--", color=c, lw=0.8, ms=3, alpha=0.6)
        for k in drone.flagged_segments:
            (x0, y0), (x1, y1) = path[k], path[k + 1]
            ground.plot([x0, x1], [y0, y1], color="red", lw=6, alpha=0.25)
        flown = [en(lat, lon) for _, lat, lon, _ in tracks.flown[ident]]
        if len(flown) > 1:
            ground.plot(*zip(*flown, strict=True), color=c, lw=1.6, label=f"drone {ident} flown")
            for tail, head in _arrows(flown, ARROWS):
                ground.annotate(
                    "",
                    head,
                    tail,
                    arrowprops={"arrowstyle": "-|>", "color": c, "mutation_scale": 18, "lw": 0},
                )
    # Of a busy sky, only the pairs that came near are labelled: those shown for a false
    # alarm were hundreds of metres apart, and their labels piled up over one another (the
    # report lists every figure).
    near = NEAR_FACTOR * report.separation_m
    many = len(report.drones) > FEW
    for pair in shown_pairs(report):
        a, b = pair.drones
        _, t, pa, pb = closest(tracks.flown[a], tracks.flown[b])
        if math.isfinite(pair.closest_approach_m):
            (xa, ya), (xb, yb) = en(pa[0], pa[1]), en(pb[0], pb[1])
            ground.plot([xa, xb], [ya, yb], "k:", lw=1)
            ground.plot([xa, xb], [ya, yb], "kx", ms=8)
            came = min(pair.closest_approach_m, pair.closest_approach_baseline_m) <= near
            if not many or pair.conflict or came:
                label = f"{a}-{b}: {pair.closest_approach_m:.1f} m at {t:.0f} s"
                ground.annotate(label, (xa, ya), fontsize=7)
    ground.plot([], [], color="red", lw=6, alpha=0.25, label="flagged segments")
    ground.plot([], [], "kx", label="closest approach")
    ground.set(xlabel="east (m)", ylabel="north (m)", title=f"{report.scenario}: ground tracks")
    ground.set_aspect("equal", adjustable="datalim")


def _gaps(gap: Any, report: ReplayReport, tracks: Tracks, colour: dict[int, str]) -> None:
    """The 3-D distance of every pair over time, with and without the companions, and the
    moments of the runs and edits that concern the pair (of a busy sky, the pairs that came
    near: :func:`companion.sim.report.shown_pairs`)."""
    pairs = shown_pairs(report)
    if not pairs:
        near = NEAR_FACTOR * report.separation_m
        gap.text(
            0.5, 0.5, f"no pair came within {near:.0f} m", transform=gap.transAxes, ha="center"
        )
        window = _flight_window(tracks.flown)
        if window is not None:
            gap.set_xlim(*window)
    for pair in pairs:
        a, b = pair.drones
        for which, style in ((tracks.flown, "-"), (tracks.baseline, ":")):
            series = _separation(which[a], which[b])
            if series:
                gap.plot(
                    *zip(*series, strict=True),
                    style,
                    lw=1.4 if style == "-" else 1,
                    label=f"{a}-{b} {'with' if style == '-' else 'without'} companion",
                )
        for drone in report.drones:
            if drone.id not in (a, b):
                continue
            other = b if drone.id == a else a
            for event in drone.timeline:
                if event["kind"] in MARKERS and event.get("peer", other) == other:
                    marker, _ = MARKERS[event["kind"]]
                    gap.axvline(event["t_s"], color=colour[drone.id], lw=0.4, alpha=0.5)
                    gap.plot(event["t_s"], 0, marker, color=colour[drone.id], ms=8, clip_on=False)
    for marker, label in MARKERS.values():
        gap.plot([], [], marker, color="grey", label=label)
    gap.axhline(report.offset_m, color="red", lw=0.8, ls="--", label="offset")
    gap.set(xlabel="simulated time (s)", ylabel="3-D distance (m)", title="distance of each pair")
    gap.set_yscale("symlog", linthresh=20)


def _heights(height: Any, report: ReplayReport, tracks: Tracks, colour: dict[int, str]) -> None:
    """Altitudes, planned and flown, over the window in which anything flies."""
    for drone in report.drones:
        ident, c = drone.id, colour[drone.id]
        for which, style, label in (
            (tracks.baseline, "--", "planned"),
            (tracks.flown, "-", "flown"),
        ):
            track = which[ident]
            height.plot(
                [p[0] for p in track],
                [p[3] for p in track],
                style,
                color=c,
                lw=1 if style == "--" else 1.5,
                label=f"drone {ident} {label}",
            )
    window = _flight_window(tracks.flown)
    if window is not None:  # hours on the ground waiting for airtime would hide the flight
        height.set_xlim(*window)
    height.set(
        xlabel="simulated time (s)",
        ylabel="altitude AMSL (m)",
        title="altitude while flying",
    )


def _legend(panel: Any, *, outside: bool) -> None:
    """The panel's legend: over the chart where it fits (a few drones), else
    below the panel, in as many columns as it needs."""
    if not outside:
        panel.legend(loc="best", fontsize=7)
        return
    entries = len(panel.get_legend_handles_labels()[1])
    panel.legend(
        loc="upper center",
        bbox_to_anchor=(0.5, -0.12),
        fontsize=7,
        ncol=max(1, math.ceil(entries / 6)),
        frameon=False,
    )


def _flight_window(flown: dict[int, Track], margin_s: float = 30.0) -> tuple[float, float] | None:
    """From the first take-off to the last landing (any drone 2 m above where it started)."""
    airborne = [
        t for track in flown.values() if track for t, *_, alt in track if alt > track[0][3] + 2.0
    ]
    if not airborne:
        return None
    return max(min(airborne) - margin_s, 0.0), max(airborne) + margin_s


ARROWS = 6  # direction arrows along each flown track


def _arrows(
    points: list[tuple[float, float]], count: int
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """(tail, head) of ``count`` short arrows spread evenly by distance along ``points`` (a
    track that holds still for minutes still gets its arrows where it moves)."""
    steps = [math.dist(p, q) for p, q in itertools.pairwise(points)]
    length = sum(steps)
    if length <= 0:
        return []
    out, walked, k = [], 0.0, 0
    for n in range(count):
        goal = length * (n + 0.5) / count
        while k < len(steps) - 1 and walked + steps[k] < goal:
            walked += steps[k]
            k += 1
        (x0, y0), (x1, y1) = points[k], points[k + 1]
        if steps[k] == 0:
            continue
        f = (goal - walked) / steps[k]
        dx, dy = (x1 - x0) / steps[k], (y1 - y0) / steps[k]
        x, y = x0 + f * (x1 - x0), y0 + f * (y1 - y0)
        size = length * 0.01
        out.append(((x - dx * size, y - dy * size), (x + dx * size, y + dy * size)))
    return out


def _separation(a: Track, b: Track) -> list[tuple[float, float]]:
    """3-D distance of two trajectories over time (b at a's times), 2000 points at most."""
    return separation(a, b)[:: max(1, len(a) // 2000)]
