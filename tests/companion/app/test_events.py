"""The companion's typed events: which kinds are failures, by set membership."""

from __future__ import annotations

from companion.events import FAILED, FAILURES, WARNINGS, Event, EventKind


def test_failed_is_set_membership_and_covers_every_failure_kind() -> None:
    """Every ``*_failed`` kind is in FAILED (a new one must be added there); the kinds that
    fail a replay are failures, and every failure is logged as a warning."""
    assert {k for k in EventKind if k.value.endswith("_failed")} == FAILED
    assert FAILURES - {EventKind.MISSION_INVALID} <= FAILED <= WARNINGS
    assert Event(0.0, EventKind.RUN_FAILED, {}).failed
    assert not Event(0.0, EventKind.RESULT, {}).failed
    assert not Event(0.0, EventKind.PRECAUTIONARY, {}).failed
