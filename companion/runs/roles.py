"""The two roles of a run (the paper's Alice and Bob), as a type rather than strings."""

from __future__ import annotations

from enum import StrEnum


class Role(StrEnum):
    ALICE = "alice"  # compares her path with the peer's and learns, per segment, if it crosses
    BOB = "bob"  # answers with his path and learns nothing
