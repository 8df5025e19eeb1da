"""Mission files: QGroundControl ``.plan`` (JSON) and MAVLink ``QGC WPL 110`` text.

Reading is strict: anything malformed raises :class:`~companion.mission.MissionError` naming
the item (plan) or line (WPL).  Writing goes to a temporary file renamed over the target, so a
failure never leaves a half-written mission.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .mission import FRAMES_GLOBAL, MissionError, MissionItem, normalise

WPL_HEADER = "QGC WPL 110"
MAX_FILE_BYTES = 16 << 20


def _read(path: str | Path) -> str:
    p = Path(path)
    try:
        if p.stat().st_size > MAX_FILE_BYTES:
            raise MissionError(f"{p}: larger than {MAX_FILE_BYTES} bytes")
        return p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionError(f"{p}: {exc}") from None


def _write_atomic(path: str | Path, text: str) -> None:
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent or ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _xy(frame: int, lat: float, lon: float) -> tuple[int, int]:
    if frame in FRAMES_GLOBAL:
        return round(lat * 1e7), round(lon * 1e7)
    return round(lat), round(lon)


def _num(value: Any, where: str) -> float:
    if value is None:
        return math.nan  # QGC writes NaN as null
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MissionError(f"{where}: expected a number, got {value!r}")
    return float(value)


def _checked(item: MissionItem, where: str) -> MissionItem:
    try:
        item.check()
    except MissionError as exc:
        raise MissionError(f"{where}: {exc}") from None
    return item


def _complete(items: list[MissionItem], name: str) -> list[MissionItem]:
    if not items:
        raise MissionError(f"{name}: the mission has no items")
    return normalise(items)


# ---------------------------------------------------------------------------- .plan


def parse_plan_items(text: str, name: str = "plan") -> tuple[list[MissionItem], tuple[float, ...]]:
    """Mission items and the planned home (lat, lon, alt) of a QGC plan."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise MissionError(f"{name}: not JSON ({exc})") from None
    mission = doc.get("mission") if isinstance(doc, dict) else None
    if not isinstance(mission, dict) or not isinstance(mission.get("items"), list):
        raise MissionError(f"{name}: no mission.items list")
    home_raw = mission.get("plannedHomePosition")
    if not isinstance(home_raw, list) or len(home_raw) != 3:
        raise MissionError(f"{name}: plannedHomePosition must be [lat, lon, alt]")
    home = tuple(_num(v, f"{name}: home") for v in home_raw)
    items = []
    for number, raw in enumerate(mission["items"]):
        where = f"{name}: mission item {number}"
        if not isinstance(raw, dict):
            raise MissionError(f"{where}: not an object")
        if raw.get("type") != "SimpleItem":
            raise MissionError(
                f"{where}: {raw.get('type')!r} items are not supported "
                "(convert complex items to waypoints in QGroundControl)"
            )
        params = raw.get("params")
        if not isinstance(params, list) or len(params) != 7:
            raise MissionError(f"{where}: params must be a list of 7")
        p = [_num(v, where) for v in params]
        command, frame = raw.get("command"), raw.get("frame")
        if not isinstance(command, int) or not isinstance(frame, int):
            raise MissionError(f"{where}: command and frame must be integers")
        if frame in FRAMES_GLOBAL and not (math.isfinite(p[4]) and math.isfinite(p[5])):
            p[4] = p[5] = 0.0  # a NAV item without a position (e.g. takeoff here)
        x, y = _xy(
            frame, p[4] if math.isfinite(p[4]) else 0.0, p[5] if math.isfinite(p[5]) else 0.0
        )
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
            p[6] if math.isfinite(p[6]) else 0.0,
        )
        items.append(_checked(item, where))
    return _complete(items, name), home


def read_plan(path: str | Path) -> tuple[list[MissionItem], tuple[float, ...]]:
    return parse_plan_items(_read(path), str(path))


def format_plan(items: Sequence[MissionItem], home: Sequence[float]) -> str:
    def coord(item: MissionItem, value: int) -> float:
        return value / 1e7 if item.frame in FRAMES_GLOBAL else float(value)

    def num(v: float) -> float | None:
        return None if math.isnan(v) else v

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


def write_plan(path: str | Path, items: Sequence[MissionItem], home: Sequence[float]) -> None:
    _write_atomic(path, format_plan(items, home))


# ---------------------------------------------------------------------------- QGC WPL 110


def parse_wpl(text: str, name: str = "mission") -> list[MissionItem]:
    """``QGC WPL 110``: one tab-separated item per line (seq current frame command p1-p4
    lat lon alt autocontinue)."""
    lines = text.splitlines()
    if not lines or lines[0].strip() != WPL_HEADER:
        raise MissionError(f"{name}: line 1: expected {WPL_HEADER!r}")
    items: list[MissionItem] = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        where = f"{name}: line {number}"
        if len(fields) != 12:
            raise MissionError(f"{where}: expected 12 fields, found {len(fields)}")
        try:
            seq, current, frame, command = (int(f) for f in fields[:4])
            p = [float(f) for f in fields[4:11]]
            autocontinue = int(fields[11])
        except ValueError as exc:
            raise MissionError(f"{where}: {exc}") from None
        if seq != len(items):
            raise MissionError(f"{where}: sequence number {seq}, expected {len(items)}")
        x, y = _xy(frame, p[4], p[5])
        item = MissionItem(
            seq, frame, command, current, autocontinue, p[0], p[1], p[2], p[3], x, y, p[6]
        )
        items.append(_checked(item, where))
    return _complete(items, name)


def read_wpl(path: str | Path) -> list[MissionItem]:
    return parse_wpl(_read(path), str(path))


def format_wpl(items: Sequence[MissionItem]) -> str:
    rows = [WPL_HEADER]
    for it in items:
        lat = it.x / 1e7 if it.frame in FRAMES_GLOBAL else float(it.x)
        lon = it.y / 1e7 if it.frame in FRAMES_GLOBAL else float(it.y)
        fields = [
            it.seq,
            it.current,
            it.frame,
            it.command,
            it.param1,
            it.param2,
            it.param3,
            it.param4,
            f"{lat:.7f}",
            f"{lon:.7f}",
            it.z,
            it.autocontinue,
        ]
        rows.append("\t".join(str(f) for f in fields))
    return "\n".join(rows) + "\n"


def write_wpl(path: str | Path, items: Sequence[MissionItem]) -> None:
    _write_atomic(path, format_wpl(items))


def read_mission(path: str | Path) -> list[MissionItem]:
    """Either format, by content."""
    text = _read(path)
    if text.lstrip().startswith(WPL_HEADER):
        return parse_wpl(text, str(path))
    return parse_plan_items(text, str(path))[0]
