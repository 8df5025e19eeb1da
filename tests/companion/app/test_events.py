"""The companion's typed events: which kinds are failures, by set membership."""

from __future__ import annotations

from companion.events import (
    FAILED,
    FAILURES,
    WARNINGS,
    Event,
    EventKind,
    PeerFailure,
    Precaution,
    RunResult,
)
from companion.roles import Phase


def test_failed_is_set_membership_and_covers_every_failure_kind() -> None:
    """Every ``*_failed`` kind is in FAILED (a new one must be added there); the kinds that
    fail a replay are failures, and every failure is logged as a warning."""
    assert {k for k in EventKind if k.value.endswith("_failed")} == FAILED
    assert FAILURES - {EventKind.MISSION_INVALID} <= FAILED <= WARNINGS
    failed = Event(0.0, EventKind.RUN_FAILED, PeerFailure(2, Phase.NEAR, error="gone"))
    assert failed.failed
    assert not Event(0.0, EventKind.RESULT, RunResult(2, Phase.FULL, [], 0, [], 1, 0, 0, 0)).failed
    assert not Event(
        0.0, EventKind.PRECAUTIONARY, Precaution(2, "climb", [1], 0, 9, None, True)
    ).failed


def test_detail_names_what_the_payload_carries() -> None:
    """Logs and JSON get the payload by name: optional fields left out when absent, required
    ones kept even when None (a time to meet that is not known)."""
    failed = Event(1.0, EventKind.RUN_FAILED, PeerFailure(2, Phase.NEAR, error="gone"))
    assert failed.detail == {"peer": 2, "phase": "near", "error": "gone"}
    precaution = Event(1.0, EventKind.PRECAUTIONARY, Precaution(2, "climb", [1], 0, 9, None, True))
    assert precaution.detail["time_to_meet_s"] is None and precaution.detail["segments"] == [1]
