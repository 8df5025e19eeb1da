"""What each party sees of a compact run is distributed the same whatever the other's path.

Bob's view, taken from his machine after honest runs: his shares of every compared value
(products, modulo 2^(l+1)), his leaf shares (one table entry per digit), Alice's triple
corrections and every opening Alice sends in the circuit rounds.  Alice's view: Bob's OT
extension and choice corrections, his digit corrections and his circuit openings (her last
message is her answer, which is allowed to differ).  Two runs whose answers differ must give
views no two-sample test can tell apart; negative controls switch off one mask each and must
be caught by the same tests, so the tests can fail.
"""

from __future__ import annotations

import secrets
from collections import Counter
from typing import Any

import pytest

import protocol.compact.products as products_module
from protocol.geo.grid import GridKind, GridSpec
from protocol.geo.volumes import SEPARATION_SIZE
from protocol.intersection import Alice, Bob
from protocol.messages import HEADER_SIZE, NONCE_SIZE
from protocol.tools.loopback import run_paths
from protocol.wire.bitpack import unpack_bits
from tests.protocol.test_privacy import chi2_rejects, ks_rejects

RUNS = 60
# A negative control's difference is systematic: fewer runs show it (measured: 8-10 of 205
# positions differ at 40 runs without leaf masks, 0-2 at 20; 21 of 582 at 20 without choice masks)
LEAF_CONTROL_RUNS, CHOICE_CONTROL_RUNS = 40, 20
GRID = GridSpec(GridKind.PLANE, 99)
BOB_PATH = ((0, 10), (10, 0))
CROSSING = ((0, 0), (10, 10))
FAR = ((50, 50), (60, 61))
BOB_FAR = ((-50, -40), (-60, -20))


def one_run(alice_path: Any, bob_path: Any, ot_pair: Any) -> tuple[Any, Any, list[bytes]]:
    alice = Alice(alice_path, GRID, setup=ot_pair.holder)
    bob = Bob(bob_path, setups=ot_pair.setups)
    received: list[bytes] = []
    original = alice.receive

    def spy(data: bytes) -> Any:
        received.append(data)
        return original(data)

    alice.receive = spy  # type: ignore[method-assign]
    run_paths(alice, bob)
    return alice, bob, received


def bob_view(
    alice_path: Any, ot_pair: Any, runs: int = RUNS
) -> tuple[list[float], list[list[int]]]:
    values: list[float] = []
    bits: list[list[int]] = []
    for _ in range(runs):
        alice, bob, _ = one_run(alice_path, BOB_PATH, ot_pair)
        assert alice.hits == [alice_path is CROSSING]
        impl: Any = bob._impl
        l = impl.plan.l
        values += [v / 2**l for v in impl.leaves.values]
        gmw = impl.gmw
        run_bits = [gmw.shares[w] for w in impl.plan.circuit.inputs]
        for level in sorted(gmw._peer):
            run_bits += gmw._peer[level]
        bits.append(run_bits + impl._highs)
    return values, bits


def alice_view(
    bob_path: Any, ot_pair: Any, *, honest: bool = True, runs: int = RUNS
) -> list[list[int]]:
    views = []
    for _ in range(runs):
        alice, _, received = one_run(CROSSING, bob_path, ot_pair)
        assert not honest or alice.hits == [bob_path is BOB_PATH]
        offer = received[0][HEADER_SIZE + 2 + NONCE_SIZE + SEPARATION_SIZE :]  # after n, Bob's
        # nonce and his separation minima (public)
        flips = offer[-alice._impl.plan.products.correction_size() :]
        digits = received[1][HEADER_SIZE:]
        run_bits = unpack_bits(offer[:40], 320)  # OT extension
        for part in (flips, digits):  # choice corrections (whole bytes)
            run_bits += unpack_bits(part[:-1], 8 * len(part) - 8)
        gmw: Any = alice._impl.gmw
        for level in sorted(gmw._peer):
            run_bits += gmw._peer[level]
        views.append(run_bits)
    return views


def indistinguishable(bits1: list[list[int]], bits2: list[list[int]]) -> list[int]:
    """Positions whose bit distributions differ between the two sets of runs."""
    return [
        p
        for p in range(len(bits1[0]))
        if chi2_rejects(Counter(r[p] for r in bits1), Counter(r[p] for r in bits2))
    ]


def pooled_ones(*sets: list[list[int]]) -> float:
    bits = [b for runs in sets for run in runs for b in run]
    return sum(bits) / len(bits)


@pytest.mark.slow
def test_bobs_view_does_not_depend_on_alices_path(ot_pair: Any) -> None:
    v1, bits1 = bob_view(CROSSING, ot_pair)
    v2, bits2 = bob_view(FAR, ot_pair)
    assert not ks_rejects(v1, v2)
    assert indistinguishable(bits1, bits2) == []
    assert 0.45 < pooled_ones(bits1, bits2) < 0.55


@pytest.mark.slow
def test_alices_view_does_not_depend_on_bobs_path(ot_pair: Any) -> None:
    bits1, bits2 = alice_view(BOB_PATH, ot_pair), alice_view(BOB_FAR, ot_pair)
    assert indistinguishable(bits1, bits2) == []
    assert 0.45 < pooled_ones(bits1, bits2) < 0.55


@pytest.mark.slow
def test_negative_control_unmasked_leaves_are_caught(ot_pair: Any, monkeypatch: Any) -> None:
    """Without Alice's random leaf shares, Bob's table entries are the comparison bits."""
    monkeypatch.setattr(secrets, "randbits", lambda k: 0)
    _, bits1 = bob_view(CROSSING, ot_pair, LEAF_CONTROL_RUNS)
    _, bits2 = bob_view(FAR, ot_pair, LEAF_CONTROL_RUNS)
    assert indistinguishable(bits1, bits2) != []


@pytest.mark.slow
def test_negative_control_unmasked_choices_are_caught(ot_pair: Any, monkeypatch: Any) -> None:
    """Without Bob's random choice bits, his product corrections are his coordinates' bits."""
    original = products_module.ProductsBob.corrections

    def plain(self: Any) -> bytes:
        self.rots = type(self.rots)(tuple(0 for _ in self.rots.choices), self.rots.keys)
        return original(self)

    monkeypatch.setattr(products_module.ProductsBob, "corrections", plain)
    far = alice_view(BOB_FAR, ot_pair, honest=False, runs=CHOICE_CONTROL_RUNS)
    near = alice_view(BOB_PATH, ot_pair, honest=False, runs=CHOICE_CONTROL_RUNS)
    assert indistinguishable(far, near) != []
