"""Mission files: .plan and QGC WPL 110, round trips and clear errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from companion.mission import MissionError
from companion.missionfile import (
    format_plan,
    format_wpl,
    parse_plan_items,
    parse_wpl,
    read_mission,
    write_plan,
    write_wpl,
)

from .missions import HOME, survey


def test_round_trips(tmp_path: Path) -> None:
    items = survey(23)
    items[0] = items[0].replace(current=1)
    write_plan(tmp_path / "m.plan", items, HOME)
    write_wpl(tmp_path / "m.txt", items)
    for name in ("m.plan", "m.txt"):
        back = read_mission(tmp_path / name)
        assert len(back) == len(items)
        assert all(a.same_as(b) for a, b in zip(items, back, strict=True))
    assert not list(tmp_path.glob(".m.*"))  # no temporary files left behind


def test_plan_nan_params_survive() -> None:
    items, home = parse_plan_items(format_plan(survey(3), HOME))
    assert math.isnan(items[0].param4) and home == HOME


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.pop("mission"), "no mission.items"),
        (lambda d: d["mission"]["items"][1].update(type="ComplexItem"), "mission item 1"),
        (lambda d: d["mission"]["items"][2].update(params=[0, 0]), "item 2: params"),
        (lambda d: d["mission"]["items"][0]["params"].__setitem__(4, 123.0), "item 0"),
        (lambda d: d["mission"]["items"][0].update(command="16"), "must be integers"),
        (lambda d: d["mission"].update(items=[]), "no items"),
    ],
)
def test_plan_errors_name_the_item(mutate, message: str) -> None:  # type: ignore[no-untyped-def]
    doc = json.loads(format_plan(survey(4), HOME))
    mutate(doc)
    with pytest.raises(MissionError, match=message):
        parse_plan_items(json.dumps(doc))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("QGC WPL 100\n", "line 1"),
        ("QGC WPL 110\n0\t1\t0\t16\n", "line 2: expected 12 fields"),
        ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\tx\t8.5\t30\t1\n", "line 2"),
        ("QGC WPL 110\n1\t1\t0\t16\t0\t0\t0\t0\t47.3\t8.5\t30\t1\n", "sequence number 1"),
        ("QGC WPL 110\n0\t1\t42\t16\t0\t0\t0\t0\t47.3\t8.5\t30\t1\n", "unknown frame"),
    ],
)
def test_wpl_errors_name_the_line(text: str, message: str) -> None:
    with pytest.raises(MissionError, match=message):
        parse_wpl(text)


def test_mission_show_cli(tmp_path: Path) -> None:
    path = tmp_path / "m.txt"
    path.write_text(format_wpl(survey(7)))
    run = subprocess.run(
        [sys.executable, "-m", "companion", "mission", "show", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stderr
    assert "segment 0: item 0 -> item 1" in run.stdout and "DO_CHANGE_SPEED" in run.stdout
    bad = tmp_path / "bad.txt"
    bad.write_text("QGC WPL 110\n0\t1\n")
    run = subprocess.run(
        [sys.executable, "-m", "companion", "mission", "show", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2 and "line 2" in run.stderr
