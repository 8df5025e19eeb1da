"""Mission files: QGroundControl ``.plan`` (JSON) and MAVLink ``QGC WPL 110`` text.

Reading is strict: anything malformed raises :class:`~companion.mission.items.MissionError` naming
the item (plan) or line (WPL).  Formatting gives the file's text (the command line writes it
atomically: a failure never leaves a half-written mission).
"""

from __future__ import annotations

from pathlib import Path

from companion.mission.files.common import WPL_HEADER, MissionFile, _read, shift_jumps
from companion.mission.files.plan import (
    format_plan,
    parse_plan_file,
    parse_plan_items,
    read_plan,
)
from companion.mission.files.wpl import format_wpl, parse_wpl, parse_wpl_file, read_wpl
from companion.mission.items import MissionItem

__all__ = [
    "MissionFile",
    "format_plan",
    "format_wpl",
    "parse_plan_file",
    "parse_plan_items",
    "parse_wpl",
    "parse_wpl_file",
    "read_mission",
    "read_mission_file",
    "read_plan",
    "read_wpl",
    "shift_jumps",
]


def read_mission_file(path: str | Path) -> MissionFile:
    """Either format, by content."""
    text = _read(path)
    if text.lstrip().startswith(WPL_HEADER):
        return parse_wpl_file(text, str(path))
    return parse_plan_file(text, str(path))


def read_mission(path: str | Path) -> list[MissionItem]:
    """The mission items of either format (home excluded)."""
    return read_mission_file(path).items
