"""``QGC WPL 110`` text: one item per line, item 0 is home (as QGroundControl, MAVProxy and
ArduPilot read it); and writing one back."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from companion.mission.files.common import (
    WPL_HEADER,
    MissionFile,
    _checked,
    _complete,
    _read,
    _xy,
    shift_jumps,
)
from companion.mission.items import (
    FRAMES_GLOBAL,
    NAV_WAYPOINT,
    POSITIONAL_NAV,
    MissionError,
    MissionItem,
)


def parse_wpl_file(text: str, name: str = "mission") -> MissionFile:
    """``QGC WPL 110``: one item per line (seq current frame command p1-p4 lat lon alt
    autocontinue, tab- or space-separated).  Read as QGroundControl, MAVProxy and ArduPilot
    read it: the first item is home, the rest is the mission; ``#`` lines are comments and
    sequence numbers only order the lines (a file may start at 1)."""
    lines = text.splitlines()
    if not lines or lines[0].strip() != WPL_HEADER:
        raise MissionError(f"{name}: line 1: expected {WPL_HEADER!r}")
    items: list[MissionItem] = []
    last_seq = -1
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = line.split()
        where = f"{name}: line {number}"
        if len(fields) != 12:
            raise MissionError(f"{where}: expected 12 fields, found {len(fields)}")
        try:
            seq, current, frame, command = (int(f) for f in fields[:4])
            p = [float(f) for f in fields[4:11]]
            autocontinue = int(fields[11])
        except ValueError as exc:
            raise MissionError(f"{where}: {exc}") from None
        if seq <= last_seq:
            raise MissionError(f"{where}: sequence number {seq} after {last_seq}")
        last_seq = seq
        if any(math.isinf(v) for v in p):
            raise MissionError(f"{where}: a parameter is infinite")
        if frame in FRAMES_GLOBAL and command in POSITIONAL_NAV:
            if not math.isfinite(p[6]):
                raise MissionError(f"{where}: altitude is not a number")
            if not all(map(math.isfinite, p[4:6])):  # "here" is 0, 0 in a WPL file
                raise MissionError(f"{where}: latitude/longitude is not a number")
        x, y = _xy(frame, p[4], p[5]) if all(map(math.isfinite, p[4:6])) else (0, 0)
        item = MissionItem(
            len(items),
            frame,
            command,
            current,
            autocontinue,
            p[0],
            p[1],
            p[2],
            p[3],
            x,
            y,
            p[6] if math.isfinite(p[6]) else 0.0,
        )
        items.append(_checked(item, where))
    if not items:
        raise MissionError(f"{name}: no items (the first line after the header is home)")
    first = items[0]
    if first.frame not in FRAMES_GLOBAL or (first.x, first.y) == (0, 0):
        raise MissionError(f"{name}: the first item is home and needs a position")
    home = (first.x / 1e7, first.y / 1e7, first.z)
    rest = [it.replace(seq=i) for i, it in enumerate(items[1:])]  # jumps counted home as 0
    return MissionFile(_complete(shift_jumps(rest, -1), name), home)


def parse_wpl(text: str, name: str = "mission") -> list[MissionItem]:
    """The mission items of a WPL file (home excluded)."""
    return parse_wpl_file(text, name).items


def read_wpl(path: str | Path) -> list[MissionItem]:
    return parse_wpl(_read(path), str(path))


def format_wpl(items: Sequence[MissionItem], home: Sequence[float]) -> str:
    """WPL with ``home`` (lat, lon, alt AMSL) as item 0, the items after it."""
    first = MissionItem(
        0, 0, NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, round(home[0] * 1e7), round(home[1] * 1e7), home[2]
    )
    rows = [WPL_HEADER]
    for it in [first, *(it.replace(seq=i + 1) for i, it in enumerate(shift_jumps(items, +1)))]:
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
