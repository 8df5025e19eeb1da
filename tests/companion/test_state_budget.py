"""The companion's state on disk and the run budget it keeps (probing mitigation)."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.budget import ALICE, BOB, BudgetExceeded, RunLedger, RunLimits, Scope
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
