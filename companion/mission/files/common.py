"""What both mission file formats share: reading a file, numbers, checked items, the
:class:`MissionFile` they both give."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.mission.flightpath import DO_JUMP
from companion.mission.items import (
    FRAMES_GLOBAL,
    NAV_TAKEOFF,
    NAV_VTOL_TAKEOFF,
    NAV_WAYPOINT,
    MissionError,
    MissionItem,
    normalise,
)

WPL_HEADER = "QGC WPL 110"
MAX_FILE_BYTES = 16 << 20


def _read(path: str | Path) -> str:
    p = Path(path)
    try:
        if p.stat().st_size > MAX_FILE_BYTES:
            raise MissionError(f"{p}: larger than {MAX_FILE_BYTES} bytes")
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MissionError(f"{p}: does not exist") from None
    except IsADirectoryError:
        raise MissionError(f"{p}: is a directory") from None
    except OSError as exc:  # one line without the "[Errno N]" of str(exc)
        raise MissionError(f"{p}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise MissionError(f"{p}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None


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
    item.check(where)
    return item


def shift_jumps(items: Sequence[MissionItem], delta: int) -> list[MissionItem]:
    """DO_JUMP targets (param1, an item number) moved by ``delta``: a home item added in
    front (+1, ArduPilot and WPL count home as item 0) or taken away (-1)."""
    return [
        it.replace(param1=it.param1 + delta)
        if it.command == DO_JUMP and math.isfinite(it.param1)
        else it
        for it in items
    ]


def _complete(items: list[MissionItem], name: str) -> list[MissionItem]:
    if not items:
        raise MissionError(f"{name}: the mission has no items")
    return normalise(items)


@dataclass(frozen=True)
class MissionFile:
    """A mission as a file states it: the items to fly (without any home item) and the
    planned home (lat, lon, alt AMSL), if the file gives one."""

    items: list[MissionItem]
    home: tuple[float, float, float] | None

    @property
    def home_degE7(self) -> tuple[int, int] | None:
        return None if self.home is None else (round(self.home[0] * 1e7), round(self.home[1] * 1e7))

    def for_autopilot(self, *, ardupilot: bool = False) -> list[MissionItem]:
        """The items as the autopilot should hold them: ArduPilot's item 0 is home; PX4
        takes a take-off's latitude/longitude literally, so a take-off "here" (0,0 in the
        file) gets home's position, as QGroundControl writes it."""
        if not ardupilot:
            home = self.home_degE7
            return normalise(
                [
                    it.replace(x=home[0], y=home[1])
                    if home is not None
                    and it.command in (NAV_TAKEOFF, NAV_VTOL_TAKEOFF)
                    and it.frame in FRAMES_GLOBAL
                    and (it.x, it.y) == (0, 0)
                    else it
                    for it in self.items
                ]
            )
        if self.home is None:
            raise MissionError("an ArduPilot mission needs a home (item 0): the file has none")
        lat, lon = self.home_degE7 or (0, 0)
        home_item = MissionItem(0, 0, NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, lat, lon, self.home[2])
        return normalise([home_item, *shift_jumps(self.items, +1)])


def _finite(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
