"""``python -m protocol compare`` end to end, as a user runs it (a real subprocess)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from protocol.tools.bench_paths import format_paper
from tests.paper_shaped import PaperShaped


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "protocol", *args], capture_output=True, text=True, timeout=300
    )


def test_compare_json(tmp_path: Path) -> None:
    alice, bob = tmp_path / "alice.txt", tmp_path / "bob.txt"
    alice.write_text("(0,0)(10,10)\n(0,0)(5,0)(5,5)\n")
    bob.write_text("(0,10)(10,0)\n(5,0)(9,0)\n")
    result = run_cli("compare", str(alice), str(bob), "--json")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert (
        out["suite"] == "compact" and out["params"]["comparison_bits"] == 11
    )  # range 10: 2^11 > 16 * 100 + 1
    first, second = out["cases"]
    assert first["hits"] == first["plain_hits"] == [True]
    assert second["hits"] == second["plain_hits"] == [True, True]
    for case in out["cases"]:
        assert 8 <= case["messages"] <= 16 and case["messages"] % 2 == 0  # Bob sends the last
        assert case["round_trips"] == case["messages"] // 2  # Alice's turns, each answered
        sizes = case["message_sizes"]  # every message, in order, repeated names kept
        assert len(sizes) == case["messages"] and sizes[0][0] == "HELLO"
        sent = sum(size for _, size in sizes)
        assert sent == case["bytes_alice_to_bob"] + case["bytes_bob_to_alice"]
        assert case["bytes_alice_to_bob"] > 0 and case["cpu_s_bob"] > 0


@pytest.mark.parametrize(
    ("alice", "bob", "message"),
    [
        ("(0,0)(1,1)\n", "(0,0)(1,1)\n(2,2)(3,3)\n", "has 1 paths"),
        ("(0,0)\n", "(0,0)(1,1)\n", "two points"),
    ],
)
def test_compare_refuses_bad_input(tmp_path: Path, alice: str, bob: str, message: str) -> None:
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text(alice)
    b.write_text(bob)
    result = run_cli("compare", str(a), str(b))
    assert result.returncode == 2 and message in result.stderr
    assert "Traceback" not in result.stderr


def test_demo_runs_and_agrees_with_the_plaintext() -> None:
    result = run_cli("demo")
    assert result.returncode == 0, result.stderr
    assert "CROSSES" in result.stdout and "Bob learns nothing." in result.stdout


def test_compare_sends_mission_files_to_the_companion(tmp_path: Path) -> None:
    """Two .plan missions: their flown path is the companion's model (launch leg, loiters,
    RTL), so ``python -m protocol compare`` points to ``python -m companion compare``
    (tests/companion/test_over_link.py)."""

    def plan(points: list[tuple[float, float]]) -> str:
        items = [
            {
                "type": "SimpleItem",
                "command": 16,
                "frame": 3,
                "params": [0, 0, 0, None, lat, lon, 30],
                "doJumpId": i + 1,
            }
            for i, (lat, lon) in enumerate(points)
        ]
        return json.dumps(
            {
                "fileType": "Plan",
                "version": 1,
                "groundStation": "QGroundControl",
                "mission": {
                    "version": 2,
                    "items": items,
                    "plannedHomePosition": [*points[0], 0],
                    "firmwareType": 12,
                    "vehicleType": 2,
                    "cruiseSpeed": 15,
                    "hoverSpeed": 5,
                },
                "geoFence": {"circles": [], "polygons": [], "version": 2},
                "rallyPoints": {"points": [], "version": 2},
            }
        )

    alice, bob = tmp_path / "alice.plan", tmp_path / "bob.plan"
    alice.write_text(plan([(47.3977, 8.5456), (47.3977, 8.5500), (47.3990, 8.5500)]))
    bob.write_text(plan([(47.3960, 8.5480), (47.3995, 8.5480)]))
    # mission files are compared on the path the autopilot flies: the companion's model
    refused = run_cli("compare", str(alice), str(bob), "--json")
    assert refused.returncode == 2 and "python -m companion compare" in refused.stderr


@pytest.mark.slow
def test_bench_paper_reads_the_data_directory(paper_shaped: PaperShaped) -> None:
    """``bench paper --data DIR``: the pairs and the routes of a directory in the paper's
    layout (here the project's own data of that shape), each answered correctly."""
    result = run_cli("bench", "paper", "--data", str(paper_shaped.directory), "--json", "--quiet")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["data"] == str(paper_shaped.directory)
    assert out["pairs"]["runs"] == out["pairs"]["correct"] == 30
    assert out["first_contact"]["runs"] == out["first_contact"]["correct"] == 30
    routes = {r["route"]: r for r in out["routes"]}
    for number, expected in paper_shaped.route_hits.items():
        assert routes[number]["hit_indices"] == expected
        assert routes[number]["expected_any"] is bool(expected)
    assert "| correct | 30/30 |" in format_paper(out)  # the table the command prints
