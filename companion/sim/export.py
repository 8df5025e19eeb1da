"""A replay's flights as files other tools open: CSV tracks, KML (Google Earth, QGroundControl)
and GeoJSON (QGIS, geojson.io, any web map).

``python -m companion replay SCENARIO --export DIR`` writes:

- ``tracks.csv``: every drone's flown track, one row per sample
  (``drone,t_s,lat_deg,lon_deg,alt_m_amsl``);
- ``encounter.kml``: per drone its planned path, its flown track (3-D, absolute altitude) and
  the segments its comparisons flagged, plus each pair's closest approach;
- ``encounter.geojson``: the same as GeoJSON features (coordinates lon, lat, alt AMSL).

Each file is written whole or not at all (:func:`protocol.tools.cli.write_atomic`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any
from xml.etree import ElementTree as ET

from companion.sim.vehicles import Track
from protocol.tools import cli

if TYPE_CHECKING:
    from companion.sim.replay import Replay

KML_NS = "http://www.opengis.net/kml/2.2"
COLOURS = ("ff1f77b4", "ff0e7fff", "ff2ca02c", "ff2827d6", "ffbd6794", "ff4b568c")  # aabbggrr


def tracks_csv(tracks: Mapping[int, Track]) -> str:
    """Flown tracks as CSV, one row per sample; with a drone column for more than one
    (``tracks`` keyed by drone, or by 0 for a single vehicle's own track)."""
    many = len(tracks) > 1
    head = ("drone," if many else "") + "t_s,lat_deg,lon_deg,alt_m_amsl\n"
    return head + "".join(
        f"{f'{ident},' if many else ''}{t:.2f},{lat:.7f},{lon:.7f},{alt:.2f}\n"
        for ident, track in sorted(tracks.items())
        for t, lat, lon, alt in track
    )


def _planned(points: Sequence[tuple[int, int]], alt: float) -> list[tuple[float, float, float]]:
    return [(lat / 1e7, lon / 1e7, alt) for lat, lon in points]


def features(replay: Replay) -> list[dict[str, Any]]:
    """GeoJSON features of a :class:`~companion.sim.replay.Replay`."""
    report, tracks = replay.report, replay.tracks
    out: list[dict[str, Any]] = []

    def line(points: Sequence[tuple[float, float, float]], **props: Any) -> None:
        coords = [[round(lon, 7), round(lat, 7), round(alt, 2)] for lat, lon, alt in points]
        out.append(
            {
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": coords},
                "properties": props,
            }
        )

    for drone in report.drones:
        ident = drone.id
        flown = [(lat, lon, alt) for _, lat, lon, alt in tracks.flown[ident]]
        ground = flown[0][2] if flown else 0.0
        planned = _planned(tracks.paths[ident], ground)
        line(planned, drone=ident, kind="planned path", altitude="ground level")
        if len(flown) > 1:
            line(flown, drone=ident, kind="flown track", altitude="m AMSL")
        for k in drone.flagged_segments:
            if k + 1 < len(planned):
                line(planned[k : k + 2], drone=ident, kind="flagged segment", segment=k)
    for pair in report.pairs:
        a, b = pair.drones
        when = pair.closest_approach_t_s
        ends = [_at(tracks.flown[d], when) for d in (a, b)]
        if all(e is not None for e in ends):
            line(
                [e for e in ends if e is not None],
                kind="closest approach",
                drones=[a, b],
                distance_m=pair.closest_approach_m,
                t_s=when,
            )
    return out


def _at(track: Track, t: float) -> tuple[float, float, float] | None:
    """The sample of ``track`` nearest time ``t``."""
    if not track:
        return None
    _, lat, lon, alt = min(track, key=lambda s: abs(s[0] - t))
    return lat, lon, alt


def kml(replay: Replay, placemarks: list[dict[str, Any]]) -> str:
    """The encounter as a KML document (``placemarks``: its :func:`features`)."""
    ET.register_namespace("", KML_NS)
    root = ET.Element(f"{{{KML_NS}}}kml")
    doc = ET.SubElement(root, f"{{{KML_NS}}}Document")
    ET.SubElement(doc, f"{{{KML_NS}}}name").text = f"replay {replay.report.scenario}"
    order = {d.id: n for n, d in enumerate(replay.report.drones)}
    for feature in placemarks:
        props = feature["properties"]
        kind = props["kind"]
        mark = ET.SubElement(doc, f"{{{KML_NS}}}Placemark")
        who = (
            f"drone {props['drone']}"
            if "drone" in props
            else "drones {}-{}".format(*props["drones"])
        )
        extra = (
            f" {props['segment']}"
            if "segment" in props
            else f" {props['distance_m']:.1f} m at {props['t_s']:.0f} s"
            if "distance_m" in props
            else ""
        )
        ET.SubElement(mark, f"{{{KML_NS}}}name").text = f"{who}: {kind}{extra}"
        style = ET.SubElement(mark, f"{{{KML_NS}}}Style")
        line_style = ET.SubElement(style, f"{{{KML_NS}}}LineStyle")
        colour = (
            "ff0000ff"  # red
            if kind == "flagged segment"
            else "ff000000"
            if kind == "closest approach"
            else COLOURS[order.get(props.get("drone", 0), 0) % len(COLOURS)]
        )
        ET.SubElement(line_style, f"{{{KML_NS}}}color").text = colour
        width = {"flagged segment": "6", "flown track": "3"}.get(kind, "1.5")
        ET.SubElement(line_style, f"{{{KML_NS}}}width").text = width
        geometry = ET.SubElement(mark, f"{{{KML_NS}}}LineString")
        absolute = kind in ("flown track", "closest approach")
        mode = "absolute" if absolute else "clampToGround"
        ET.SubElement(geometry, f"{{{KML_NS}}}altitudeMode").text = mode
        ET.SubElement(geometry, f"{{{KML_NS}}}coordinates").text = " ".join(
            f"{lon},{lat},{alt}" for lon, lat, alt in feature["geometry"]["coordinates"]
        )
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode")


def export(replay: Replay, directory: Path) -> list[Path]:
    """Write the three files into ``directory`` (created if its parent exists)."""
    directory.mkdir(exist_ok=True)
    placemarks = features(replay)
    collection = {"type": "FeatureCollection", "features": placemarks}
    files = {
        "tracks.csv": tracks_csv(replay.tracks.flown),
        "encounter.kml": kml(replay, placemarks),
        "encounter.geojson": json.dumps(collection, indent=1) + "\n",
    }
    written = []
    for name, text in files.items():
        path = directory / name
        cli.write_atomic(path, text)
        written.append(path)
    return written
