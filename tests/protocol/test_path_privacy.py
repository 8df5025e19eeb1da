"""Bob's view of a path run is distributed the same whatever Alice's path (and answer).

Bob's view, recomputed from the frames with his own keys: every masked value he decrypts
(message 3), which comparison-test sets contain a zero (message 5), and the level-1 shares he
zero-tests (message 7).  Two Alice segments, one crossing Bob's and one far away, must give
views no two-sample test can tell apart; the negative control shows the same test does tell
apart the sign bits the paper's code reveals.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import pytest

from protocol.geometry import orient
from protocol.grid import GridKind, GridSpec
from protocol.intersection import Alice, Bob
from protocol.loopback import run_paths
from protocol.wire import HEADER_SIZE, Suite

from .test_privacy import chi2_rejects, ks_rejects

RUNS = 50
GRID = GridSpec(GridKind.PLANE, 99)
BOB_PATH = ((0, 10), (10, 0))
CROSSING = ((0, 0), (10, 10))
FAR = ((50, 50), (60, 61))


def bob_view(alice_path: Any, keys: Any) -> tuple[list[float], list[list[int]]]:
    values: list[float] = []
    bits: list[list[int]] = []
    for _ in range(RUNS):
        frames: list[bytes] = []
        alice = Alice(alice_path, GRID, {Suite.COMPACT: keys.alice[Suite.COMPACT]})
        bob = Bob(BOB_PATH, keys.bob)
        original = bob.receive

        def spy(data: bytes, original: Any = original, frames: list[bytes] = frames) -> Any:
            frames.append(data)
            return original(data)

        bob.receive = spy  # type: ignore[method-assign]
        run_paths(alice, bob)
        assert alice.hits == [alice_path is CROSSING]
        paillier, ec = keys.bob.paillier, keys.bob.bits[Suite.COMPACT]
        masked = frames[1][HEADER_SIZE:]
        width = paillier.public_key.ciphertext_width
        top = 1 << (bob.l + bob.kappa + 1)
        for k in range(len(masked) // width):
            ct = paillier.public_key.ciphertext_from_bytes(masked[k * width : (k + 1) * width])
            packed = paillier.decrypt(ct)
            slots = sum(p.length for p in bob.layout.ciphertexts[k])
            values += [((packed >> (bob.w * s)) & ((1 << bob.w) - 1)) / top for s in range(slots)]
        size, group = ec.public_key.token_size, bob.l + 1
        tests = frames[2][HEADER_SIZE:]
        run_bits = []
        for start in range(0, len(tests), size * group):
            chunk = tests[start : start + size * group]
            run_bits.append(
                int(any(ec.token_is_zero(chunk[j * size : (j + 1) * size]) for j in range(group)))
            )
        level1 = frames[3][HEADER_SIZE:]
        run_bits += [int(not ec.token_is_zero(level1[j * size : (j + 1) * size])) for j in range(4)]
        bits.append(run_bits)
    return values, bits


@pytest.mark.slow
def test_bobs_view_does_not_depend_on_alices_path(path_keys: Any) -> None:
    v1, bits1 = bob_view(CROSSING, path_keys)
    v2, bits2 = bob_view(FAR, path_keys)
    assert not ks_rejects(v1, v2)
    for position in range(len(bits1[0])):
        a = Counter(run[position] for run in bits1)
        b = Counter(run[position] for run in bits2)
        assert not chi2_rejects(a, b), f"bit {position} differs"
    ones = sum(map(sum, bits1 + bits2))
    total = sum(map(len, bits1 + bits2))
    assert 0.4 < ones / total < 0.6  # shares are uniform bits
    # Negative control: a sign bit the paper's code hands out, [orient(C, D, A) >= 0] for
    # Alice's first vertex, differs -- and the same test sees it.
    signs1 = Counter([int(orient(*BOB_PATH, CROSSING[0]) >= 0)] * RUNS)
    signs2 = Counter([int(orient(*BOB_PATH, FAR[0]) >= 0)] * RUNS)
    assert chi2_rejects(signs1, signs2)


def test_alice_receives_only_ciphertexts_and_her_bits(path_keys: Any) -> None:
    """Every byte Alice receives parses as keys, ciphertexts under Bob's keys, or the final
    counts under her key, whose zero tests are exactly her answer."""
    from protocol.encoding import Reader
    from protocol.wire import KeysHeader, MsgType, unframe

    frames: list[bytes] = []
    own = path_keys.alice[Suite.COMPACT]
    alice = Alice(((0, 0), (10, 10), (20, 0)), GRID, {Suite.COMPACT: own})
    bob = Bob(BOB_PATH, path_keys.bob)
    original = alice.receive

    def spy(data: bytes) -> Any:
        frames.append(data)
        return original(data)

    alice.receive = spy  # type: ignore[method-assign]
    run_paths(alice, bob)
    keys_frame, bits_frame, gates_frame, counts_frame = frames
    paillier = path_keys.bob.paillier.public_key
    ec = path_keys.bob.bits[Suite.COMPACT].public_key
    reader = Reader(unframe(keys_frame, MsgType.KEYS))
    head = KeysHeader.read(reader)
    assert head.paillier_key == paillier.to_bytes() and head.bits_key == ec.to_bytes()
    while reader.remaining():
        paillier.read_ciphertext(reader)  # validates membership in Z*_{n^2}
    for data, kind in ((bits_frame, MsgType.BITS), (gates_frame, MsgType.GATES)):
        body = unframe(data, kind)
        reader = Reader(body)
        ec.read_batch(reader, (len(body) - 16) // 33)  # a nonce and curve points, nothing else
        reader.finish()
    counts = unframe(counts_frame, MsgType.COUNTS)
    size = own.public_key.token_size
    zero = [
        own.token_is_zero(counts[i * size : (i + 1) * size]) for i in range(len(counts) // size)
    ]
    assert [not z for z in zero][: len(alice.hits)] == alice.hits
