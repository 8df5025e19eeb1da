"""``python -m protocol demo``: two drones near the PX4 SITL home compare their missions

Embedded defaults: Alice's and Bob's missions as WGS84 waypoints (degE7) around Zurich, the
PX4 SITL default home.  Alice's hello carries the grid (tangent plane at her home, 0.5 m cells);
Bob projects his own waypoints on it.  Both parties run the real protocol through its byte
encoding (compact suite), twice: the first run with a peer carries the one-time OT setup, the
second reuses it.  The demo prints each message's size, each party's CPU time, and Alice's
answer next to the plaintext predicate (which neither drone could compute alone).
"""

from __future__ import annotations

from protocol.geo.geometry import path_hits
from protocol.geo.grid import GridSpec
from protocol.intersection import Alice, Bob
from protocol.ot.setup import ChooserSetup
from protocol.tools.loopback import run_paths

HOME_LAT, HOME_LON = 473_977_420, 85_455_940  # PX4 SITL default home (degE7)
# Alice surveys east-west legs; Bob flies a north-south transit through her second leg.
ALICE_MISSION = (
    (HOME_LAT, HOME_LON),
    (HOME_LAT + 9_000, HOME_LON),
    (HOME_LAT + 9_000, HOME_LON + 26_000),
    (HOME_LAT + 13_500, HOME_LON + 26_000),
    (HOME_LAT + 13_500, HOME_LON),
)
BOB_MISSION = (
    (HOME_LAT - 4_500, HOME_LON + 13_000),
    (HOME_LAT + 5_000, HOME_LON + 13_000),
    (HOME_LAT + 11_000, HOME_LON + 15_000),
    (HOME_LAT + 22_000, HOME_LON + 40_000),
)


def run_demo() -> int:
    grid = GridSpec.geo(HOME_LAT, HOME_LON, radius_m=2000)
    alice_path = grid.project_path(ALICE_MISSION)
    print(
        f"Grid: tangent plane at {HOME_LAT / 1e7:.6f}, {HOME_LON / 1e7:.6f}, "
        f"{grid.resolution_mm / 1000} m cells, range +-{grid.range} -> l = {grid.l} bits"
    )
    print(
        f"Alice: {len(alice_path) - 1} segments; Bob: {len(BOB_MISSION) - 1} segments "
        "(Bob's waypoints never leave Bob)"
    )
    setups: dict[bytes, ChooserSetup] = {}
    setup = None
    runs = []
    for label in ("first run (one-time OT setup)", "second run (setup cached)"):
        alice = Alice(alice_path, grid, setup=setup)
        bob = Bob(BOB_MISSION, setups=setups, geographic=True)
        runs.append((label, run_paths(alice, bob)))
        setup = alice.setup
    print("\n| message | " + " | ".join(label for label, _ in runs) + " |")
    print("|---|" + "---:|" * len(runs))
    for row in zip(*(t.sizes for _, t in runs), strict=True):
        print(f"| {row[0][0]} | " + " | ".join(str(size) for _, size in row) + " |")
    for label, t in runs:
        print(
            f"\n{label}: {t.bytes_alice_to_bob} B Alice->Bob, {t.bytes_bob_to_alice} B "
            f"Bob->Alice, {t.messages} messages; CPU Alice {1e3 * t.cpu_alice:.0f} ms, "
            f"Bob {1e3 * t.cpu_bob:.0f} ms."
        )
    plain = path_hits(alice_path, grid.project_path(BOB_MISSION))
    print("\nAlice learns, per segment of her mission:")
    for index, (hit, truth) in enumerate(zip(alice.hits, plain, strict=True)):
        verdict = "CROSSES Bob's path -> altitude change needed" if hit else "clear"
        print(f"  segment {index}: {verdict}   (plaintext check: {truth})")
    print("Bob learns nothing.")
    if alice.hits != plain:
        print("MISMATCH with the plaintext predicate")
        return 1
    return 0
