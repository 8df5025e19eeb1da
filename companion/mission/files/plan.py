"""QGroundControl ``.plan`` (JSON): simple items, complex items expanded (survey, corridor and
structure scans, landing patterns), the planned home; and writing one back."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from companion.mission.files.common import (
    MissionFile,
    _checked,
    _complete,
    _finite,
    _num,
    _read,
    _xy,
)
from companion.mission.flightpath import DO_JUMP
from companion.mission.items import (
    FRAMES_GLOBAL,
    NAV_LAND,
    NAV_LOITER_TO_ALT,
    NAV_TAKEOFF,
    NAV_VTOL_LAND,
    NAV_VTOL_TAKEOFF,
    NAV_WAYPOINT,
    POSITIONAL_NAV,
    MissionError,
    MissionItem,
)
from protocol.geo.geodesy import metres_per_degree

# commands that may stand "here", without a position (QGC writes null lat/lon for them)
POSITION_OPTIONAL = frozenset({NAV_TAKEOFF, NAV_VTOL_TAKEOFF, NAV_LAND, NAV_VTOL_LAND})
ALT_CALC_ABOVE_TERRAIN = 3  # QGC's AltitudeMode "calculated above terrain"
FRAME_TERRAIN = 10  # MAV_FRAME_GLOBAL_TERRAIN_ALT
NULL_ALTITUDE_HINT = (
    "QGroundControl writes null when an altitude 'calculated above terrain' had no terrain "
    "data: open the plan with terrain data and save it again, or give the altitude"
)


def _simple_item(raw: dict[str, Any], number: int, where: str) -> MissionItem:
    params = raw.get("params")
    if not isinstance(params, list) or len(params) != 7:
        raise MissionError(f"{where}: params must be a list of 7")
    p = [_num(v, where) for v in params]
    command, frame = raw.get("command"), raw.get("frame")
    if not isinstance(command, int) or not isinstance(frame, int):
        raise MissionError(f"{where}: command and frame must be integers")
    if isinstance(raw.get("autoContinue"), bool | int | None) is False:
        raise MissionError(f"{where}: autoContinue must be true or false")
    x = y = 0
    z = p[6]
    if frame in FRAMES_GLOBAL and command in POSITIONAL_NAV:
        if not (math.isfinite(p[4]) and math.isfinite(p[5])):
            if command not in POSITION_OPTIONAL:
                raise MissionError(f"{where}: command {command} needs a latitude and longitude")
            p[4] = p[5] = 0.0  # take off / land where the vehicle is
        if not math.isfinite(z):
            above = raw.get("Altitude")
            if (
                raw.get("AltitudeMode") != ALT_CALC_ABOVE_TERRAIN
                or not isinstance(above, int | float)
                or not _finite(above)
            ):
                raise MissionError(f"{where}: altitude is null ({NULL_ALTITUDE_HINT})")
            # "calculated above terrain" without terrain data: what the file still says is
            # the height above terrain, which is MAV_FRAME_GLOBAL_TERRAIN_ALT (ArduPilot
            # flies it; PX4 refuses terrain frames, and the upload says so before sending)
            frame, z = FRAME_TERRAIN, float(above)
    elif not math.isfinite(z):
        z = 0.0  # a command without a position: its param7 is not an altitude
    if frame in FRAMES_GLOBAL:
        x, y = _xy(frame, p[4], p[5])
    else:
        x, y = _xy(frame, *(v if math.isfinite(v) else 0.0 for v in (p[4], p[5])))
    item = MissionItem(
        number,
        frame,
        command,
        0,
        int(bool(raw.get("autoContinue", True))),
        p[0],
        p[1],
        p[2],
        p[3],
        x,
        y,
        z,
    )
    return _checked(item, where)


def _offset_ring(
    polygon: list[tuple[float, float]], distance_m: float
) -> list[tuple[float, float]]:
    """A polygon (lat, lon degrees) pushed ``distance_m`` outward: each edge moved out, the
    new corners where neighbouring moved edges meet (QGC's structure-scan flight ring)."""
    lat0, lon0 = polygon[0]
    ky, kx = metres_per_degree(lat0)
    pts = [((lon - lon0) * kx, (lat - lat0) * ky) for lat, lon in polygon]
    area = sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(pts, pts[1:] + pts[:1], strict=True))
    sign = 1.0 if area > 0 else -1.0  # outward normal of a counter-clockwise ring: (dy, -dx)
    lines = []
    for a, b in zip(pts, pts[1:] + pts[:1], strict=True):
        dx, dy = b[0] - a[0], b[1] - a[1]
        length = math.hypot(dx, dy) or 1.0
        nx, ny = sign * dy / length, -sign * dx / length
        lines.append(((a[0] + nx * distance_m, a[1] + ny * distance_m), (dx, dy)))
    out = []
    for (p1, d1), (p2, d2) in zip(lines[-1:] + lines[:-1], lines, strict=True):
        cross = d1[0] * d2[1] - d1[1] * d2[0]
        if abs(cross) < 1e-9:
            x, y = p2
        else:
            t = ((p2[0] - p1[0]) * d2[1] - (p2[1] - p1[1]) * d2[0]) / cross
            x, y = p1[0] + t * d1[0], p1[1] + t * d1[1]
        out.append((lat0 + y / ky, lon0 + x / kx))
    return out


def _complex_items(raw: dict[str, Any], where: str) -> list[MissionItem]:
    """The items QGroundControl uploads for a complex item: survey and corridor scans carry
    them (``TransectStyleComplexItem.Items``); a structure scan is rebuilt from its polygon
    (one ring per layer, at the scan distance); landing patterns from their loiter and
    landing points."""
    kind = raw.get("complexItemType")
    transect = raw.get("TransectStyleComplexItem")
    if isinstance(transect, dict) and isinstance(transect.get("Items"), list):
        out = []
        for k, sub in enumerate(transect["Items"]):
            if not isinstance(sub, dict) or sub.get("type") != "SimpleItem":
                raise MissionError(f"{where} ({kind}): generated item {k} is not a SimpleItem")
            out.append(_simple_item(sub, k, f"{where} ({kind}) generated item {k}"))
        if not out:
            raise MissionError(f"{where} ({kind}): no generated items (save it in QGC again)")
        return out
    if kind == "StructureScan":
        return _structure_scan(raw, where)
    if kind in ("fwLandingPattern", "vtolLandingPattern"):
        return _landing_pattern(raw, where)
    raise MissionError(
        f"{where}: complex item {kind!r} without generated items is not supported "
        "(convert it to waypoints in QGroundControl)"
    )


def _structure_scan(raw: dict[str, Any], where: str) -> list[MissionItem]:
    poly = raw.get("polygon")
    camera = raw.get("CameraCalc")
    if not isinstance(poly, list) or len(poly) < 3 or not isinstance(camera, dict):
        raise MissionError(f"{where} (StructureScan): needs a polygon and CameraCalc")
    points = [(_num(p[0], where), _num(p[1], where)) for p in poly if isinstance(p, list)]
    distance = _num(camera.get("DistanceToSurface", 0.0), where)
    layers = int(_num(raw.get("Layers", 1), where))
    bottom = _num(raw.get("ScanBottomAlt", 0.0), where)
    height = _num(raw.get("StructureHeight", 0.0), where)
    entrance = _num(raw.get("EntranceAltitude", bottom), where)
    values = [*(c for p in points for c in p), distance, bottom, height, entrance]
    if len(points) < 3 or not all(math.isfinite(v) for v in values) or not 1 <= layers <= 100:
        raise MissionError(f"{where} (StructureScan): polygon, distance or layers invalid")
    ring = _offset_ring(points, distance)
    frame = 3  # QGC scans relative to home
    out: list[MissionItem] = []

    def wp(lat: float, lon: float, alt: float) -> None:
        x, y = _xy(frame, lat, lon)
        out.append(MissionItem(len(out), frame, NAV_WAYPOINT, 0, 1, 0, 0, 0, math.nan, x, y, alt))

    wp(*ring[0], entrance)
    step = height / layers
    for layer in range(layers):
        alt = bottom + step * (layer + 0.5)
        for lat, lon in [*ring, ring[0]]:
            wp(lat, lon, alt)
    wp(*ring[0], entrance)
    return [_checked(it, f"{where} (StructureScan)") for it in out]


def _landing_pattern(raw: dict[str, Any], where: str) -> list[MissionItem]:
    kind = raw.get("complexItemType")
    loiter, land = raw.get("loiterCoordinate"), raw.get("landCoordinate")
    if not (isinstance(loiter, list) and isinstance(land, list) and len(loiter) == len(land) == 3):
        raise MissionError(f"{where} ({kind}): needs loiterCoordinate and landCoordinate")
    lo = [_num(v, where) for v in loiter]
    la = [_num(v, where) for v in land]
    radius = _num(raw.get("loiterRadius", 0.0), where)
    if not all(math.isfinite(v) for v in (*lo, *la, radius)):
        raise MissionError(f"{where} ({kind}): coordinates must be numbers")
    frame = 3 if raw.get("altitudesAreRelative", True) else 0
    lx, ly = _xy(frame, lo[0], lo[1])
    dx, dy = _xy(frame, la[0], la[1])
    out = [
        MissionItem(0, 2, 189, 0, 1, 0, 0, 0, 0, 0, 0, 0.0),  # DO_LAND_START
        MissionItem(1, frame, NAV_LOITER_TO_ALT, 0, 1, 1, radius, 0, 1, lx, ly, lo[2]),
        MissionItem(2, frame, NAV_LAND, 0, 1, 0, 0, 0, math.nan, dx, dy, la[2]),
    ]
    return [_checked(it, f"{where} ({kind})") for it in out]


def _no_constant(token: str) -> float:
    """JSON has no NaN or Infinity (Python's reader takes them): a file with one was not
    written by QGroundControl, which writes null for a missing value."""
    raise MissionError(f"{token} is not a JSON number (a missing value is null)")


def parse_plan_file(text: str, name: str = "plan") -> MissionFile:
    """A QGroundControl plan: its items (complex items expanded) and planned home."""
    try:
        doc = json.loads(text, parse_constant=_no_constant)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise MissionError(f"{name}: not JSON ({exc})") from None
    except MissionError as exc:
        raise MissionError(f"{name}: {exc}") from None
    mission = doc.get("mission") if isinstance(doc, dict) else None
    if not isinstance(mission, dict) or not isinstance(mission.get("items"), list):
        raise MissionError(f"{name}: no mission.items list")
    home_raw = mission.get("plannedHomePosition")
    if not isinstance(home_raw, list) or len(home_raw) != 3:
        raise MissionError(f"{name}: plannedHomePosition must be [lat, lon, alt]")
    hlat, hlon, halt = (_num(v, f"{name}: home") for v in home_raw)
    if not (math.isfinite(hlat) and math.isfinite(hlon)):
        raise MissionError(f"{name}: plannedHomePosition has no latitude/longitude")
    if not (-90 <= hlat <= 90 and -180 <= hlon <= 180):
        raise MissionError(f"{name}: plannedHomePosition outside the globe")
    home = (hlat, hlon, halt if math.isfinite(halt) else 0.0)
    items: list[MissionItem] = []
    jump_ids: dict[int, int] = {}  # doJumpId -> index of the item in ``items``
    for number, raw in enumerate(mission["items"]):
        where = f"{name}: mission item {number}"
        if not isinstance(raw, dict):
            raise MissionError(f"{where}: not an object")
        jump_id = raw.get("doJumpId")
        if isinstance(jump_id, int) and not isinstance(jump_id, bool):
            jump_ids.setdefault(jump_id, len(items))
        if raw.get("type") == "SimpleItem":
            items.append(_simple_item(raw, len(items), where))
        elif raw.get("type") == "ComplexItem":
            items.extend(_complex_items(raw, where))
        else:
            raise MissionError(f"{where}: unknown item type {raw.get('type')!r}")
    items = [_jump_by_id(it.replace(seq=i), jump_ids, name) for i, it in enumerate(items)]
    return MissionFile(_complete(items, name), home)


def _jump_by_id(item: MissionItem, jump_ids: dict[int, int], name: str) -> MissionItem:
    """A .plan's DO_JUMP names its target by ``doJumpId`` (QGroundControl turns it into the
    item number on load): here the index in the mission without home."""
    if item.command != DO_JUMP:
        return item
    target = item.param1
    if not math.isfinite(target) or int(target) not in jump_ids:
        raise MissionError(
            f"{name}: mission item {item.seq}: DO_JUMP to doJumpId {target}: no item has it"
        )
    return item.replace(param1=float(jump_ids[int(target)]))


def parse_plan_items(text: str, name: str = "plan") -> tuple[list[MissionItem], tuple[float, ...]]:
    """Mission items and the planned home (lat, lon, alt) of a QGC plan."""
    plan = parse_plan_file(text, name)
    return plan.items, plan.home or ()


def read_plan(path: str | Path) -> tuple[list[MissionItem], tuple[float, ...]]:
    return parse_plan_items(_read(path), str(path))


def format_plan(items: Sequence[MissionItem], home: Sequence[float]) -> str:
    def coord(item: MissionItem, value: int) -> float:
        return value / 1e7 if item.frame in FRAMES_GLOBAL else float(value)

    def num(v: float) -> float | None:
        return None if math.isnan(v) else v

    items = [  # DO_JUMP names its target by doJumpId, item k's being k + 1
        it.replace(param1=it.param1 + 1) if it.command == DO_JUMP else it for it in items
    ]
    plan_items = [
        {
            "type": "SimpleItem",
            "command": it.command,
            "frame": it.frame,
            "autoContinue": bool(it.autocontinue),
            "doJumpId": i + 1,
            "params": [
                num(it.param1),
                num(it.param2),
                num(it.param3),
                num(it.param4),
                coord(it, it.x),
                coord(it, it.y),
                it.z,
            ],
        }
        for i, it in enumerate(items)
        if it.mission_type == 0
    ]
    doc = {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "private-deconfliction",
        "mission": {
            "version": 2,
            "items": plan_items,
            "plannedHomePosition": list(home),
            "firmwareType": 12,
            "vehicleType": 2,
            "cruiseSpeed": 15,
            "hoverSpeed": 5,
        },
        "geoFence": {"circles": [], "polygons": [], "version": 2},
        "rallyPoints": {"points": [], "version": 2},
    }
    return json.dumps(doc, indent=2) + "\n"
