"""Grid projection, ranges and path file formats."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from protocol.errors import InputRangeError, RemoteProtocolError
from protocol.geo.grid import GridKind, GridSpec, comparison_bits
from protocol.tools.formats import InputFormatError, parse_paper_text

LAT, LON = 473_977_420, 85_455_940


def test_comparison_bits_cover_every_value() -> None:
    for r in (1, 2, 99, 1500, 10_000, 1 << 20):
        l = comparison_bits(r)
        assert 2**l > 16 * r * r + 1 >= 2 ** (l - 1)
    assert comparison_bits(99) == 18


def test_projection_distances() -> None:
    grid = GridSpec.geo(LAT, LON, resolution_mm=500, radius_m=5000)
    assert grid.project(LAT, LON) == (0, 0)
    x, y = grid.project(LAT + 10_000, LON)  # 0.001 degrees north, about 111.2 m
    assert x == 0 and abs(y * 0.5 - 111.2) < 0.5
    x, y = grid.project(LAT, LON + 10_000)  # east, scaled by cos(latitude)
    assert y == 0 and abs(x * 0.5 - 111.3 * math.cos(math.radians(LAT / 1e7))) < 0.5
    assert grid.range == 10_000 and grid.l == comparison_bits(10_000)


def test_out_of_range_inputs_are_refused() -> None:
    grid = GridSpec.geo(LAT, LON, radius_m=100)
    with pytest.raises(InputRangeError, match="range"):
        grid.project(LAT + 100_000, LON)  # about 1.1 km away
    with pytest.raises(InputRangeError):
        grid.project(950_000_000, LON)
    with pytest.raises(InputRangeError):
        GridSpec(GridKind.PLANE, 0)
    with pytest.raises(InputRangeError):
        GridSpec(GridKind.PLANE, 10).project(LAT, LON)
    with pytest.raises(InputRangeError):
        GridSpec(GridKind.PLANE, 10).check_points([(0, 11)])
    with pytest.raises(RemoteProtocolError):
        GridSpec.from_bytes(b"\x07" + bytes(16))
    with pytest.raises(RemoteProtocolError):
        GridSpec.from_bytes(bytes(17))  # range 0


def test_paper_format() -> None:
    cases = parse_paper_text("(1,2)(3,-4)\n\n(0,0)( 5 , 5 )(6,7)\n")
    assert cases == [((1, 2), (3, -4)), ((0, 0), (5, 5), (6, 7))]
    for bad in ("(1,2)", "(1,2)(3,4", "1,2 3,4", "(1.5,2)(3,4)", "", "(1,2)(3,99999999999)"):
        with pytest.raises(InputFormatError):
            parse_paper_text(bad)


def plan(items: list[dict[str, object]], home: list[float] | None = None) -> str:
    return json.dumps(
        {
            "fileType": "Plan",
            "mission": {"items": items, "plannedHomePosition": home or [47.397742, 8.545594, 488]},
        }
    )


def waypoint(lat: float, lon: float, command: int = 16) -> dict[str, object]:
    return {"type": "SimpleItem", "command": command, "params": [0, 0, 0, 0, lat, lon, 20]}


def test_mission_files_are_left_to_the_companion(tmp_path: Path) -> None:
    """The ground path of a mission is the companion's one model (launch leg, loiters,
    DO_JUMP, RTL): this package refuses to guess it and says where to go."""
    from protocol.tools.compare import load_cases

    a, b = tmp_path / "a.plan", tmp_path / "b.plan"
    a.write_text(plan([waypoint(47.3985, 8.5456)]))
    b.write_text(plan([waypoint(47.3980, 8.5440), waypoint(47.3980, 8.5470)]))
    with pytest.raises(InputFormatError, match="python -m companion compare"):
        load_cases(a, b)
    paper = tmp_path / "p.txt"
    paper.write_text("(0,0)(1,1)\n")
    with pytest.raises(InputFormatError, match="both files must be missions"):
        load_cases(a, paper)
