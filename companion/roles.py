"""The two roles of a run (the paper's Alice and Bob) and the two phases of Alice's comparison
with a peer, as types rather than strings."""

from __future__ import annotations

from enum import StrEnum


class Role(StrEnum):
    ALICE = "alice"  # compares her path with the peer's and learns, per segment, if it crosses
    BOB = "bob"  # answers with his path and learns nothing


class Phase(StrEnum):
    NEAR = "near"  # what either drone can reach soon (up to a horizon), first
    FULL = "full"  # the rest of the path, when it is needed
