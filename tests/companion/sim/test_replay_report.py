"""The replay's verdict: exit 0 and "OK" only when nothing went wrong; every failure named."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from companion.sim.report import ReplayReport, format_report


def _drone(ident: int, **changes: Any) -> dict[str, Any]:
    drone = {
        "id": ident,
        "operator": "fleet",
        "autopilot": "px4",
        "vehicle": "mock",
        "segments": 2,
        "conflicting_segments": [0],
        "flagged_segments": [0] if ident == 1 else [],
        "edits": [],
        "edit": "not needed",
        "raises": {},
        "runs": [],
        "precautionary": [],
        "failures": [],
        "timeline": [],
        "runs_unfinished": 0,
        "untrusted_heard": [],
        "beacons_rejected": {},
        "auth": {"run_bytes": 200, "beacon_bytes": 500, "beacons": {}, "beacon_added_bytes": 300},
        "bytes_sent": 1000,
        "frames_sent": 10,
        "airtime_s": 2.0,
        "max_altitude_m_amsl": 528.0,
        "vehicle_holds": "edited" if ident == 1 else "original",
    }
    return drone | changes


GOOD: dict[str, Any] = {
    "scenario": "crossing",
    "link": {"profile": "us915-sf7", "loss": 0.1, "seed": 1},
    "time_scale": 40.0,
    "finished": True,
    "offset_m": 10.0,
    "drones": [_drone(1, edit="verified", raises={"0": 15.0}), _drone(2)],
    "pairs": [
        {
            "drones": [1, 2],
            "trusted": True,
            "paths_cross": True,
            "paths_near": True,
            "conflict": True,
            "acted": True,
            "resolved": True,
            "made_worse": False,
            "false_alarm": False,
            "inside_s": 0.0,
            "inside_baseline_s": 3.1,
            "closest_approach_m": 15.1,
            "closest_approach_baseline_m": 0.3,
            "closest_approach_t_s": 184.0,
            "resolved_tolerance_m": 0.5,
        }
    ],
    "conflicts": 1,
    "conflicts_resolved": 1,
    "untrusted_conflicts": 0,
    "precautionary_actions": 0,
    "false_alarms": 0,
    "made_worse": 0,
    "separation_m": 15.0,
    "vertical_separation_m": 10.0,
}


def _report(change: Any) -> ReplayReport:
    doc = copy.deepcopy(GOOD)
    change(doc)
    return ReplayReport.from_json(doc).judged()


def test_a_clean_replay_says_ok() -> None:
    report = _report(lambda r: None)
    assert report.problems == [] and report.ok
    assert ReplayReport.from_json(report.to_json()) == report  # --out reads back the same
    text = format_report(report)
    assert text.splitlines()[-1].startswith("OK: every mission flown")
    assert "flies segments 0 (+15 m) higher (upload verified)" in text
    assert "drone 2 (px4, fleet): kept its altitude (no edit needed)" in text


def _plan_failed(r: dict[str, Any]) -> None:
    r["drones"][0] |= {
        "edit": "failed",
        "raises": {},
        "failures": [{"kind": "plan_failed", "error": "item 1: -40.0 m below the minimum"}],
    }
    r["pairs"][0] |= {"conflict": False, "resolved": False}
    r["conflicts"] = r["conflicts_resolved"] = 0


def _time_limit(r: dict[str, Any]) -> None:
    r["finished"] = False


def _unresolved(r: dict[str, Any]) -> None:
    r["pairs"][0] |= {"resolved": False, "closest_approach_m": 0.6, "inside_s": 2.0}
    r["conflicts_resolved"] = 0


def _made_worse(r: dict[str, Any]) -> None:
    """A climb into the band of a drone 10 m higher: 12.6 m without, 7.9 m with."""
    r["pairs"][0] |= {
        "conflict": False,
        "resolved": False,
        "made_worse": True,
        "closest_approach_baseline_m": 12.6,
        "closest_approach_m": 7.9,
        "inside_s": 4.0,
        "inside_baseline_s": 0.0,
    }
    r["conflicts"] = r["conflicts_resolved"] = 0
    r["made_worse"] = 1


def _unfinished_run(r: dict[str, Any]) -> None:
    r["drones"][1]["runs_unfinished"] = 1


def _false_alarm(r: dict[str, Any]) -> None:
    """A climb for a drone 60 m above, which never came inside the protected volume."""
    r["pairs"][0] |= {"conflict": False, "resolved": False, "false_alarm": True}
    r["conflicts"] = r["conflicts_resolved"] = 0
    r["false_alarms"] = 1


def test_what_does_not_fail_a_replay_is_still_stated() -> None:
    """A run cut off by the end (every mission flown), a failed run that was retried and a
    precautionary action are said in the summary; only the failures above fail it."""

    def change(r: dict[str, Any]) -> None:
        r["drones"][1] |= {
            "runs_unfinished": 1,
            "failures": [{"kind": "run_failed", "error": "nothing from node 1 for 60 s"}],
            "precautionary": [{"t_s": 90.0, "action": "climb", "peer": 1}],
        }

    report = _report(change)
    assert report.problems == [] and report.ok
    text = format_report(report)
    assert "drone 2: 1 run(s) still under way at the end" in text
    assert "drone 2: 1 run(s) ended without a result (run failed)" in text
    assert "drone 2: 1 precautionary action(s)" in text
    assert text.splitlines()[-1] == (
        "OK (with notes): every mission flown, every conflict resolved; but 1 run(s) failed "
        "and were retried, 1 precautionary action(s) taken, 1 run(s) never finished "
        "(Notes above)"
    )  # never a bare "OK" under failed runs; no "verified action" claim after a precaution


def test_a_retried_run_alone_still_qualifies_the_ok() -> None:
    """A run that failed and was retried (normal on a lossy link) keeps exit 0, but the
    last line says so; the verified edit still resolved the conflict."""

    def change(r: dict[str, Any]) -> None:
        r["drones"][0]["failures"] = [{"kind": "run_failed", "error": "link timeout"}]

    report = _report(change)
    assert report.ok
    last = format_report(report).splitlines()[-1]
    assert last.startswith("OK (with notes): every mission flown, every conflict resolved by")
    assert "1 run(s) failed and were retried" in last


@pytest.mark.parametrize(
    ("change", "says"),
    [
        (_plan_failed, "drone 1: plan failed: item 1: -40.0 m below the minimum"),
        (_time_limit, "the time limit ended the replay"),
        (_unresolved, "drones 1-2: conflict NOT resolved (2 s inside the protected volume"),
        (_made_worse, "drones 1-2: made WORSE by the companion (closest approach 12.6 m"),
        (_false_alarm, "drones 1-2: false alarm (an edit or precaution, but never inside"),
    ],
)
def test_every_failure_is_stated_and_fails_the_replay(change: Any, says: str) -> None:
    """A summary never says OK for what did not happen (the planner failing with "0/0"
    conflicts once printed a clean summary and exit 0)."""
    report = _report(change)
    assert not report.ok and any(says in p for p in report.problems)
    text = format_report(report)
    assert "FAILED" in text and says in text and "OK:" not in text


def _pair(a: int, b: int, closest: float, **changes: Any) -> dict[str, Any]:
    quiet = {
        "drones": [a, b],
        "conflict": False,
        "acted": False,
        "resolved": False,
        "paths_cross": False,
        "paths_near": False,
        "inside_baseline_s": 0.0,
        "closest_approach_m": closest,
        "closest_approach_baseline_m": closest,
    }
    pair: dict[str, Any] = GOOD["pairs"][0] | quiet | changes
    return pair


def _busy_sky(r: dict[str, Any]) -> None:
    """Five drones: 1-2 resolved as in GOOD (1 climbed two levels), 3-4 passed 60 m apart,
    every other pair kilometres apart."""
    r["drones"] = [
        _drone(1, edit="verified", raises={"0": 15.0}),
        *(_drone(k, flagged_segments=[]) for k in range(2, 6)),
    ]
    r["drones"][2]["precautionary"] = [{"peer": 4, "segments": [1]}]
    r["drones"][2]["edits"] = [{"raises": {"1": 10.0}}]  # the precaution's climb, undone
    r["pairs"] = [GOOD["pairs"][0]] + [
        _pair(a, b, 60.0 if (a, b) == (3, 4) else 1500.0)
        for a in range(1, 6)
        for b in range(a + 1, 6)
        if (a, b) != (1, 2)
    ]
    r["precautionary_actions"] = 1


def test_a_busy_sky_shows_the_pairs_that_came_near_and_a_table_of_drones() -> None:
    """More than three drones: a row per drone (levels above its plan, precautions, runs,
    bytes) instead of a sentence each, and only the pairs that came near (within five
    separations, or acted on) -- the other eight are counted, not listed."""
    text = format_report(_report(_busy_sky))
    lines = text.splitlines()
    header = next(i for i, line in enumerate(lines) if "levels up" in line)
    rows = [line.split() for line in lines[header + 1 : header + 6]]
    assert [row[0] for row in rows] == ["1", "2", "3", "4", "5"]
    assert rows[0][1] == "2" and rows[0][2] == "verified"  # 15 m with a 10 m offset
    assert rows[2][1:5] == ["1", "not", "needed", "1"]  # one level (undone), one precaution
    assert "drones 1-2:" in text and "drones 3-4:" in text
    assert "drones 1-3:" not in text and "drones 4-5:" not in text
    assert "8 other pair(s) never came within 75 m" in text
    small = format_report(_report(lambda r: None))
    assert "levels up" not in small and "other pair" not in small  # a small replay: all
