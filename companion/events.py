"""What a companion records of its flight: typed events for logs, reports and tests.

Each :class:`Event` has a time (link seconds since the companion's start or the replay's
zero), an :class:`EventKind` and its details (names with units: ``t_s``, ``bytes``, ...).
:class:`EventKind` is a string enum, so JSON reports and logs keep the plain names.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any


class EventKind(StrEnum):
    # the mission and the neighbourhood
    MISSION = "mission"  # read from the autopilot at start
    MISSION_INVALID = "mission_invalid"  # its flown path cannot be built: fly, compare nothing
    PEER = "peer"  # a trusted drone heard for the first time
    UNTRUSTED = "untrusted"  # a certified drone of an operator we do not trust (logged once)
    INTRUDER = "intruder"  # the same, reported with its position (policy "alert")
    # runs as Alice
    BUDGET = "budget"  # a run refused by our own run budget
    RUN_STARTED = "run_started"
    RESULT = "result"  # a run ended with an answer
    RUN_FAILED = "run_failed"  # a run ended without one (retried later)
    YIELDED = "yielded"  # the peer is Alice for this pair
    PEER_BUSY = "peer_busy"  # the peer refused: its own run is on the air (asked again soon)
    SETUP_RENEWED = "setup_renewed"  # the peer lost our OT setup: a fresh one
    # runs as Bob
    REFUSED = "refused"  # a request refused before any work
    ANSWERED = "answered"
    ANSWER_FAILED = "answer_failed"
    # acting on results
    PRECAUTIONARY = "precautionary"  # a climb or hold without a result (the fail-safe)
    FIXED_SEGMENTS = "fixed_segments"  # segments an edit may not move
    UPLOADED = "uploaded"  # an edit uploaded and verified
    UPLOAD_FAILED = "upload_failed"
    PLAN_FAILED = "plan_failed"
    HOLD = "hold"
    HOLD_FAILED = "hold_failed"
    RESUMED = "resumed"
    RESUME_FAILED = "resume_failed"
    RETIMED = "retimed"  # off its predicted windows by half the tolerance: compare again
    # the process itself
    TASK_FAILED = "task_failed"  # one of the companion's tasks raised


# logged as warnings: something went wrong, or a drone acted without a result
WARNINGS = frozenset(
    {
        EventKind.ANSWER_FAILED,
        EventKind.HOLD_FAILED,
        EventKind.INTRUDER,
        EventKind.MISSION_INVALID,
        EventKind.PLAN_FAILED,
        EventKind.PRECAUTIONARY,
        EventKind.RESUME_FAILED,
        EventKind.RUN_FAILED,
        EventKind.TASK_FAILED,
        EventKind.UPLOAD_FAILED,
    }
)
# after one of these the drone did not fly what it should have
FAILURES = frozenset(
    {
        EventKind.PLAN_FAILED,
        EventKind.UPLOAD_FAILED,
        EventKind.HOLD_FAILED,
        EventKind.RESUME_FAILED,
        EventKind.MISSION_INVALID,
        EventKind.TASK_FAILED,
    }
)
# a failure of any kind: a run, an answer, an edit, a hold or resume, a task
FAILED = frozenset(
    {
        EventKind.RUN_FAILED,
        EventKind.ANSWER_FAILED,
        EventKind.UPLOAD_FAILED,
        EventKind.PLAN_FAILED,
        EventKind.HOLD_FAILED,
        EventKind.RESUME_FAILED,
        EventKind.TASK_FAILED,
    }
)
# runs as Alice that ended, one way or the other
RUN_ENDS = frozenset(
    {
        EventKind.RESULT,
        EventKind.RUN_FAILED,
        EventKind.YIELDED,
        EventKind.SETUP_RENEWED,
        EventKind.PEER_BUSY,
    }
)


@dataclass
class Event:
    """One line of the companion's history (for logs and replay reports)."""

    t: float
    kind: EventKind
    detail: dict[str, Any]

    @property
    def failed(self) -> bool:
        """A failure of any kind (a run, an answer, an edit, a task)."""
        return self.kind in FAILED
