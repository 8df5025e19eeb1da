"""``python -m companion compare --link`` and ``bench-link`` as a user runs them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from companion.radio import PROFILES
from companion.sim.bench_link import bench_link, format_link
from companion.sim.over_link import link_case
from protocol.messages import Suite
from protocol.tools.compare import Party
from protocol.tools.paper_data import load_paper_data
from tests.paper_shaped import PaperShaped


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "companion", *args], capture_output=True, text=True, timeout=300
    )


def test_compare_over_a_lossy_link_json(tmp_path: Path) -> None:
    alice, bob = tmp_path / "alice.txt", tmp_path / "bob.txt"
    alice.write_text("(0,0)(10,10)\n(0,0)(5,0)(5,5)\n")
    bob.write_text("(0,10)(10,0)\n(5,0)(9,0)\n")
    result = run_cli(
        "compare",
        str(alice),
        str(bob),
        "--link",
        "eu868-sf9",
        "--loss",
        "0.3",
        "--seed",
        "7",
        "--json",
    )
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["link"]["profile"] == "eu868-sf9" and out["link"]["loss"] == 0.3
    for case in out["cases"]:
        assert case["hits"] == case["plain_hits"]
        assert case["frames_sent"] > case["frames_retransmitted"] > 0
        assert case["airtime_s"] > 0
        # ~10 KB at SF9 (~1.8 kbit/s) needs more than the 32 s of data budget an hour allows
        assert case["wall_s_simulated"] > case["airtime_s"]


def test_radio_demo() -> None:
    result = run_cli("radio-demo")
    assert result.returncode == 0, result.stderr
    assert "| us915-sf7 | True |" in result.stdout and "| eu868-sf7 | True |" in result.stdout


def test_compare_table_and_bad_profile(tmp_path: Path) -> None:
    alice, bob = tmp_path / "alice.txt", tmp_path / "bob.txt"
    alice.write_text("(0,0)(10,10)\n")
    bob.write_text("(0,10)(10,0)\n")
    result = run_cli("compare", str(alice), str(bob), "--link", "ideal")
    assert result.returncode == 0, result.stderr
    assert "link ideal (255-byte frames)" in result.stdout
    bad = run_cli("compare", str(alice), str(bob), "--link", "eu433")
    assert bad.returncode == 2 and "unknown link profile" in bad.stderr
    worse = run_cli("compare", str(alice), str(bob), "--link", "ideal", "--loss", "1.5")
    assert worse.returncode == 2 and "--loss: 1.5 is out of range" in worse.stderr


@pytest.mark.slow
def test_bench_link_rows(paper_shaped: PaperShaped) -> None:
    """The paper's pairs from a data directory (here the project's of their shape; the first
    10 of 30: the suite's time), on one profile at two losses (the ideal profile runs in the
    test below)."""
    data = paper_shaped.directory
    result = bench_link(data, ["us915-sf9"], (0.0, 0.3), size=2, progress=False, pairs=10)
    assert result["pairs_from"] == f"{data}, its first 10 pairs"
    rows = result["rows"]
    assert len(rows) == 2 * 3  # losses x (paper pair, first contact, 2x2)
    for row in rows:
        assert row["correct"] == row["runs"]
        assert row["frames_sent"] > 0 and row["airtime_s"] > 0
    paper = {(r["profile"], r["loss"]): r for r in rows if r["workload"] == "paper pair"}
    assert paper[("us915-sf9", 0.3)]["frames_sent"] > paper[("us915-sf9", 0.0)]["frames_sent"]
    assert paper[("us915-sf9", 0.0)]["frames_retransmitted"] == 0
    first = {
        (r["profile"], r["loss"]): r for r in rows if r["workload"] == "paper pair, first contact"
    }
    for key, row in first.items():  # the OT setup travels too
        assert row["frames_sent"] > paper[key]["frames_sent"]
    table = format_link(result)
    assert "| us915-sf9 | 30% | paper pair | 10/10 |" in table
    for row in rows:  # authenticated runs: key exchange (109 + 130 B) and a tag per message
        assert row["auth_bytes"] >= 109 + 130 + 16
    sf9 = {c["kind"]: c for c in result["beacons"]["us915-sf9"]}
    assert sf9["signed"]["frames"] == 3 and sf9["tagged, 1 neighbour"]["frames"] == 1
    assert "| us915-sf9 | signed | 138 | 3 |" in table


@pytest.mark.slow
def test_bench_link_without_data_runs_random_pairs() -> None:
    """Without ``--data`` the benchmark runs random pairs of the paper's shape (30, here the
    first 12) and says so."""
    result = bench_link(None, ["ideal"], (0.0,), size=1, progress=False, pairs=12)
    assert result["pairs_from"] == "12 random pairs in +-99"
    rows = {r["workload"]: r for r in result["rows"]}
    assert set(rows) == {"random pair", "random pair, first contact", "1x1"}
    assert rows["random pair"]["runs"] == rows["random pair"]["correct"] == 12
    assert "a random pair (12 random pairs in +-99) is one 1 x 1" in format_link(result)


def test_authentication_adds_the_key_exchange_and_a_tag_per_message(
    paper_shaped: PaperShaped,
) -> None:
    """The same run with and without authentication: the difference is 109 bytes on the
    request, 130 on the answer and 16 on every further message, and nothing else."""
    case = load_paper_data(paper_shaped.directory).pairs[0]
    party = Party.generate(Suite.COMPACT)
    plain = link_case(case, party, PROFILES["ideal"], authenticated=False)
    secure = link_case(case, party, PROFILES["ideal"])

    def sent(r: dict[str, int]) -> int:
        return r["bytes_alice_to_bob"] + r["bytes_bob_to_alice"]

    assert plain["auth_bytes"] == 0 and secure["hits"] == plain["hits"] == secure["plain_hits"]
    assert secure["messages"] == plain["messages"]
    assert secure["auth_bytes"] == sent(secure) - sent(plain)
    assert secure["auth_bytes"] == 109 + 130 + 16 * (secure["messages"] - 2)


def test_compare_mission_files_as_they_are_flown(tmp_path: Path) -> None:
    """Two mission files are compared on their flown paths: Bob's line crosses only Alice's
    launch leg (home -> first waypoint) and her RTL leg, which a positions-only reader misses."""
    from companion.mission.files import format_wpl
    from protocol.tools.cli import write_atomic
    from tests.companion.missions import item

    home = (47.3970, 8.5450, 488.0)
    alice = [item(0, 16, 47.3990, 8.5450, 30.0), item(1, 16, 47.3990, 8.5480), item(2, 20, frame=2)]
    bob = [item(0, 16, 47.3980, 8.5430, 40.0), item(1, 16, 47.3980, 8.5440, 40.0)]
    a, b = tmp_path / "alice.waypoints", tmp_path / "bob.waypoints"
    write_atomic(a, format_wpl(alice, home))
    write_atomic(b, format_wpl(bob, (47.3980, 8.5420, 488.0)))  # Bob: home west, east to 8.5440 ...
    result = run_cli("compare", str(a), str(b), "--link", "ideal", "--json")
    assert result.returncode == 0, result.stderr
    (case,) = json.loads(result.stdout)["cases"]
    # Alice flies home -> wp0 (north), wp0 -> wp1 (east), wp1 -> home (RTL): Bob's line
    # (lat 47.3980 from 8.5420 to 8.5440) stays west of her launch leg at 8.5450
    assert case["hits"] == case["plain_hits"] == [False, False, False]
    write_atomic(
        b, format_wpl([*bob, item(2, 16, 47.3980, 8.5490, 40.0)], (47.3980, 8.5420, 488.0))
    )
    result = run_cli("compare", str(a), str(b), "--link", "ideal", "--json")
    (case,) = json.loads(result.stdout)["cases"]
    assert case["hits"] == case["plain_hits"] == [True, False, True]  # launch and RTL legs
    refused = subprocess.run(
        [sys.executable, "-m", "protocol", "compare", str(a), str(b)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert refused.returncode == 2 and "python -m companion compare" in refused.stderr
