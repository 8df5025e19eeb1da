"""The companion's state on disk and the run budget it keeps (probing mitigation)."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.runs.budget import ALICE, BOB, BudgetExceeded, RunLedger, RunLimits, Scope
from companion.state import StateStore


def test_budget_per_drone_operator_and_total_survives_a_restart(tmp_path: Path) -> None:
    ledger = RunLedger(StateStore(tmp_path), RunLimits(per_drone=2, total=5, window_s=3600))
    for t in (0.0, 10.0):
        ledger.admit(b"drone-a", b"op-x", 4, t, BOB)
    with pytest.raises(BudgetExceeded) as info:
        ledger.admit(b"drone-a", b"op-x", 4, 20.0, BOB)
    assert info.value.scope is Scope.DRONE
    ledger.admit(b"drone-b", b"op-x", 4, 20.0, BOB)
    ledger.admit(b"drone-c", b"op-x", 4, 30.0, BOB)
    with pytest.raises(BudgetExceeded) as info:  # a fourth made-up drone of operator x
        ledger.admit(b"drone-d", b"op-x", 4, 40.0, BOB)
    assert info.value.scope is Scope.OPERATOR
    ledger.admit(b"drone-e", b"op-y", 4, 50.0, BOB)
    with pytest.raises(BudgetExceeded) as info:
        ledger.admit(b"drone-f", b"op-z", 4, 60.0, BOB)
    assert info.value.scope is Scope.TOTAL
    ledger.admit(b"drone-a", b"op-x", 4, 60.0, ALICE)  # our own runs are counted apart
    # a restart: a new store on the same directory remembers every run
    again = RunLedger(StateStore(tmp_path), RunLimits(per_drone=2, total=5, window_s=3600))
    with pytest.raises(BudgetExceeded):
        again.admit(b"drone-a", b"op-x", 4, 100.0, BOB)
    again.admit(b"drone-a", b"op-x", 4, 3611.0, BOB)  # the window slid past the first run


def test_replay_cache_and_counters_persist(tmp_path: Path) -> None:
    store = StateStore(tmp_path / "state")
    assert store.first_request(b"key", 100.0, 0.0)
    assert not store.first_request(b"key", 110.0, 0.0)
    store.set_counter(b"drone", 42)
    reopened = StateStore(tmp_path / "state")
    assert not reopened.first_request(b"key", 120.0, 0.0)
    assert reopened.first_request(b"key", 500.0, 200.0)  # forgotten after its window
    assert reopened.last_counter(b"drone") == 42 and reopened.last_counter(b"other") is None
    assert (tmp_path / "state").stat().st_mode & 0o777 == 0o700


def test_a_run_given_back_frees_its_place(tmp_path: Path) -> None:
    """A run that taught nothing (it ended before Bob's last message) is given back: aborted
    runs, however many, never use up a drone's budget."""
    ledger = RunLedger(StateStore(tmp_path), RunLimits(per_drone=1, total=5, window_s=3600))
    for t in range(10):  # ten runs jammed or aborted, each given back
        ledger.refund(ledger.admit(b"drone-a", b"op-x", 4, float(t), BOB))
    ledger.admit(b"drone-a", b"op-x", 4, 20.0, BOB)
    with pytest.raises(BudgetExceeded):
        ledger.admit(b"drone-a", b"op-x", 4, 21.0, BOB)


def test_answer_bits_per_drone_bound_what_one_drone_learns(tmp_path: Path) -> None:
    """D6: a deviating Alice can make each of her m output bits a predicate of her choice, so
    the budget also counts answer bits (m per run): runs of 8 segments fit many times over,
    one of 256 fits once and then nothing more that hour, whatever runs are left."""
    limits = RunLimits(per_drone=8, total=64, window_s=3600, bits_per_drone=256)
    ledger = RunLedger(StateStore(tmp_path), limits)
    ledger.admit(b"honest", b"op", 24, 0.0, BOB, bits=8)
    ledger.admit(b"honest", b"op", 24, 1.0, BOB, bits=32)
    ledger.admit(b"greedy", b"op", 24, 2.0, BOB, bits=256)
    with pytest.raises(BudgetExceeded) as info:
        ledger.admit(b"greedy", b"op", 24, 3.0, BOB, bits=2)
    assert info.value.scope is Scope.DRONE_BITS and "bits" in str(info.value)
    ledger.admit(b"greedy", b"op", 24, 3603.0, BOB, bits=2)  # the window slid on
    with pytest.raises(BudgetExceeded) as info:  # 40 + 256 > 256
        ledger.admit(b"honest", b"op", 24, 4.0, BOB, bits=256)
    assert info.value.scope is Scope.DRONE_BITS


def test_answer_bits_per_operator_bound_what_its_drones_learn_together(tmp_path: Path) -> None:
    """D6 for a cheating operator: each of its certified drones may open up to the per-drone
    bits, but all of them together only the operator's ``max_answer_bits_per_hour``; another
    operator's drones are not held back by it, and the window slides."""
    limits = RunLimits(per_drone=8, total=64, window_s=3600, bits_per_drone=256)
    ledger = RunLedger(StateStore(tmp_path), limits)
    for k, t in enumerate((0.0, 1.0, 2.0)):
        ledger.admit(b"drone-%d" % k, b"op-x", 24, t, BOB, bits=256, operator_bits=800)
    with pytest.raises(BudgetExceeded) as info:  # 768 + 64 > 800, though drone-3 is fresh
        ledger.admit(b"drone-3", b"op-x", 24, 3.0, BOB, bits=64, operator_bits=800)
    assert info.value.scope is Scope.OPERATOR_BITS and "800 bits" in str(info.value)
    ledger.admit(b"drone-3", b"op-x", 24, 3.0, BOB, bits=32, operator_bits=800)  # 800: fits
    ledger.admit(b"drone-9", b"op-y", 24, 4.0, BOB, bits=256, operator_bits=800)
    ledger.admit(b"drone-3", b"op-x", 24, 3601.5, BOB, bits=128, operator_bits=800)  # slid


def test_a_state_directory_from_before_the_bit_budget_is_upgraded(tmp_path: Path) -> None:
    import sqlite3

    db = sqlite3.connect(tmp_path / StateStore.FILE)
    db.execute("CREATE TABLE runs (t REAL, drone BLOB, operator BLOB, role TEXT)")
    db.execute("INSERT INTO runs VALUES (1.0, ?, ?, ?)", (b"d", b"o", str(BOB)))
    db.commit()
    db.close()
    store = StateStore(tmp_path)
    assert store.count_runs(0.0, BOB) == 1 and store.count_runs(0.0, BOB, bits=True) == 0
    store.record_run(2.0, b"d", b"o", BOB, bits=16)
    assert store.count_runs(0.0, BOB, drone=b"d", bits=True) == 16


@pytest.mark.parametrize(("m", "n"), [(64, 4), (16, 16), (4, 64)])
def test_a_run_at_the_work_bound_fits_the_link(m: int, n: int) -> None:
    """The work bound (m x n x grid bits) keeps every message of an admitted run -- Bob's
    first reply above all -- well inside the link's largest message, whatever its shape; the
    largest request the old limits admitted (256 x 16 on a 64 km box at 100 mm: 20 bits) is
    far beyond it."""
    from companion.radio.config import LinkConfig
    from companion.runs.budget import MAX_RUN_WORK, run_work
    from protocol.compact.plan import message_sizes
    from protocol.geo.grid import GridSpec

    grid = GridSpec(range=(1 << 16) - 1)  # 16 bits: a 64 km box at 2 m
    assert run_work(m, n, grid.range) == MAX_RUN_WORK
    sizes = message_sizes(m, n, grid, fresh_setup=True)
    assert max(size for _, size in sizes) < LinkConfig().max_message // 2
    old = GridSpec.geo(474_011_000, 85_455_940, radius_m=64_000, resolution_mm=100)
    assert run_work(256, 16, old.range) > 4 * MAX_RUN_WORK
