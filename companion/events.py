"""What a companion records of its flight: typed events for logs, reports and tests.

Each :class:`Event` has a time (link seconds since the companion's start or the replay's
zero), an :class:`EventKind` and a typed payload (a frozen dataclass; names with units:
``needed_s``, ``bytes``, ...) that reports read by attribute and logs and JSON by name.
:class:`EventKind` is a string enum, so JSON reports and logs keep the plain names.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import StrEnum
from typing import Any

from companion.roles import Phase


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


# ------------------------------------------------------------------ what each kind carries


@dataclass(frozen=True)
class MissionRead:  # MISSION
    items: int
    segments: int
    home: bool


@dataclass(frozen=True)
class Problem:  # MISSION_INVALID, PLAN_FAILED, UPLOAD_FAILED
    error: str


@dataclass(frozen=True)
class PeerHeard:  # PEER
    peer: int
    on_ground: bool
    drone: str  # the drone key's fingerprint (hex)
    operator: str


@dataclass(frozen=True)
class Stranger:  # UNTRUSTED, INTRUDER (with where it is)
    peer: int
    drone: str
    reason: str | None = None
    lat_deg_e7: int | None = None
    lon_deg_e7: int | None = None
    alt_m_amsl: float | None = None
    distance_m: int | None = None


@dataclass(frozen=True)
class PeerNote:  # YIELDED, PEER_BUSY, SETUP_RENEWED, REFUSED, RESUMED
    peer: int
    phase: Phase | None = None
    reason: str | None = None


@dataclass(frozen=True)
class PeerFailure:  # BUDGET, RUN_FAILED, ANSWER_FAILED, HOLD_FAILED, RESUME_FAILED
    """What ended it: ``error`` (ours or the peer's), ``auth`` (authentication), ``deviated``
    (the peer's OT extension failed its check) or ``refused`` (the peer's refusal code, with
    the box asked for when it refused the box)."""

    peer: int
    phase: Phase | None = None
    error: str | None = None
    auth: str | None = None
    deviated: str | None = None
    refused: str | None = None
    box_radius_m: float | None = None
    resolution_mm: int | None = None


@dataclass(frozen=True)
class RunStarted:  # RUN_STARTED
    peer: int
    phase: Phase
    segments: int
    first_segment: int
    estimate_s: float
    time_to_meet_s: float | None


@dataclass(frozen=True)
class RunResult:  # RESULT
    peer: int
    phase: Phase
    hits: list[bool]
    first_segment: int
    flagged: list[int]
    bytes: int
    auth_bytes: int
    cpu_s: float
    run_s: float


@dataclass(frozen=True)
class Answered:  # ANSWERED
    peer: int
    bytes: int
    auth_bytes: int
    guard_bytes: int


@dataclass(frozen=True)
class Precaution:  # PRECAUTIONARY
    peer: int
    action: str
    segments: list[int]
    first_segment: int
    needed_s: float
    time_to_meet_s: float | None
    waiting: bool  # no run under way with this peer yet (queued, or a retry)


@dataclass(frozen=True)
class FixedSegments:  # FIXED_SEGMENTS
    segments: list[int]
    why: str


@dataclass(frozen=True)
class Uploaded:  # UPLOADED
    flagged: list[int]
    raises: dict[str, float]  # segment (as text: JSON keys) -> metres higher
    verified: bool
    offset_m: float
    inserted: int | None
    clear_of: list[int]
    why: str


@dataclass(frozen=True)
class Hold:  # HOLD
    peer: int
    before_segment: int


@dataclass(frozen=True)
class Retimed:  # RETIMED
    epoch: int
    drift_s: float
    held: bool
    on_ground: bool


@dataclass(frozen=True)
class TaskFailed:  # TASK_FAILED
    task: str
    error: str


Payload = (
    MissionRead
    | Problem
    | PeerHeard
    | Stranger
    | PeerNote
    | PeerFailure
    | RunStarted
    | RunResult
    | Answered
    | Precaution
    | FixedSegments
    | Uploaded
    | Hold
    | Retimed
    | TaskFailed
)


@dataclass(frozen=True)
class Event:
    """One line of the companion's history (for logs and replay reports): what happened
    (``kind``) and what it carries (``payload``, typed)."""

    t: float
    kind: EventKind
    payload: Payload

    @property
    def detail(self) -> dict[str, Any]:
        """The payload as names and values (logs, JSON reports): optional fields that are
        absent are left out."""
        return {
            f.name: getattr(self.payload, f.name)
            for f in fields(self.payload)
            if not (f.default is None and getattr(self.payload, f.name) is None)
        }

    @property
    def failed(self) -> bool:
        """A failure of any kind (a run, an answer, an edit, a task)."""
        return self.kind in FAILED
