"""``make demo``: two drones near the PX4 SITL home compare their missions privately.

Embedded defaults: Alice's and Bob's missions as WGS84 waypoints (degE7) around Zurich, the
PX4 SITL default home.  Alice's hello carries the grid (tangent plane at her home, 0.5 m cells);
Bob projects his own waypoints on it.  Both parties run the real eight-message protocol through
its byte encoding (compact suite); the demo prints each message's size, each party's CPU time,
and Alice's answer next to the plaintext predicate (which neither drone could compute alone).
The flight companion (radio link, MAVLink) builds on this in later issues.
"""

from __future__ import annotations

import time

from .geometry import path_hits
from .grid import GridSpec
from .intersection import Alice, Bob, BobKeys, generate_bits_key
from .loopback import run_paths
from .wire import Suite

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
    print("Generating keys (Bob: Paillier-2048 + secp256k1; Alice: secp256k1)...", flush=True)
    start = time.process_time()
    bob_keys = BobKeys.generate((Suite.COMPACT,))
    alice_keys = {Suite.COMPACT: generate_bits_key(Suite.COMPACT)}
    print(f"  key generation {1e3 * (time.process_time() - start):.0f} ms (once per drone)")
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
    alice = Alice(alice_path, grid, alice_keys)
    bob = Bob(BOB_MISSION, bob_keys, geographic=True)
    transcript = run_paths(alice, bob)
    print("\n| message | bytes |\n|---|---:|")
    for name, size in transcript.sizes:
        print(f"| {name} | {size} |")
    print(
        f"\nTotal {transcript.bytes_alice_to_bob} B Alice->Bob, "
        f"{transcript.bytes_bob_to_alice} B Bob->Alice, {transcript.messages} messages "
        f"({transcript.round_trips:.0f} round trips); CPU Alice "
        f"{transcript.cpu_alice:.2f} s, Bob {transcript.cpu_bob:.2f} s."
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
