"""Altitude levels when several drones share the airspace (pure).

A pair of drones is deconflicted by Alice flying her conflicting segments at an offset while
Bob keeps his altitude.  With three or more drones one drone can be Alice to one peer and Bob to
another, and two climbing drones must not end up at the same height.  So climbs come in
*levels* (level L flies L offsets above the plan) and every beacon carries the set of levels
its drone flies anywhere on its remaining path.  A segment Alice must leave for peers P flies
at the lowest level >= 1 that none of P announces; when a peer announces a new level, Alice
re-plans.  With the lower node id as Alice among airborne drones the choices settle from the
highest id down (a drone that is only ever Bob stays at level 0).
"""

from __future__ import annotations

from collections.abc import Mapping

MAX_LEVEL = 7  # levels 1..7 fit the beacon's byte


def levels_mask(levels: Mapping[int, int]) -> int:
    """Bit L set for every level L >= 1 used (the beacon field)."""
    mask = 0
    for level in levels.values():
        if 1 <= level <= MAX_LEVEL:
            mask |= 1 << level
    return mask & 0xFF


def assign(conflicts: Mapping[int, set[int]], masks: Mapping[int, int]) -> dict[int, int]:
    """Segment -> level for ``conflicts`` (peer -> Alice's segments that meet its path),
    avoiding every level the peers of that segment announce (``masks``, peer -> mask)."""
    out: dict[int, int] = {}
    peers_of: dict[int, set[int]] = {}
    for peer, segments in conflicts.items():
        for segment in segments:
            peers_of.setdefault(segment, set()).add(peer)
    for segment, peers in peers_of.items():
        taken = 0
        for peer in peers:
            taken |= masks.get(peer, 0)
        level = 1
        while level < MAX_LEVEL and taken >> level & 1:
            level += 1
        out[segment] = level
    return out


def plan_levels(
    conflicts: Mapping[int, set[int]],
    precautions: Mapping[int, set[int]],
    masks: Mapping[int, int],
) -> dict[int, int]:
    """Segment -> level for the conflicts found and the precautions taken (peer -> segments):
    a precaution is a conflict until its result is in, so its level too avoids what the
    peers announce (two drones that climb for each other, or for a third, must not meet
    one offset up)."""
    merged = {peer: set(segments) for peer, segments in conflicts.items() if segments}
    for peer, segments in precautions.items():
        merged[peer] = merged.get(peer, set()) | segments
    return assign(merged, masks)
