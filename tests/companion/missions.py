"""Mission builders shared by the companion tests."""

from __future__ import annotations

import math

from companion.mission.items import MissionItem

HOME = (47.397742, 8.545594, 488.0)


def item(
    seq: int,
    command: int = 16,
    lat: float = 0.0,
    lon: float = 0.0,
    alt: float = 30.0,
    frame: int = 6,
    param1: float = 0.0,
) -> MissionItem:
    x, y = (round(lat * 1e7), round(lon * 1e7)) if frame in (0, 3, 5, 6, 10, 11) else (0, 0)
    return MissionItem(seq, frame, command, 0, 1, param1, 0.0, 0.0, math.nan, x, y, alt)


def survey(n: int, *, spacing: float = 0.0005) -> list[MissionItem]:
    """n waypoints east-west lawnmower legs, with a speed change and a servo every 5 items."""
    out = []
    for i in range(n):
        if i % 5 == 4:
            out.append(item(i, 178, frame=2, param1=5.0))  # DO_CHANGE_SPEED, no position
        else:
            lat = HOME[0] + spacing * (i // 2)
            lon = HOME[1] + (0.002 if (i // 2) % 2 else 0.0) + spacing * (i % 2)
            out.append(item(i, 16, lat, lon, 30.0 + (i % 3)))
    return out
