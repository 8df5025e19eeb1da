"""Altitudes that keep clear of conflicting peers (pure).

A pair of drones is deconflicted by Alice flying her conflicting segments higher while Bob
keeps his altitude.  How much higher is decided in absolute altitude: every beacon announces
the altitude *slots* (5 m of AMSL each) that its drone's remaining path occupies as it flies
it -- its own raises included, each band widened by its altitude error, its take-off and
landing columns left out (they lie below the altitudes it flies next to them) -- and a
flagged segment is raised by the least multiple of 5 m that is at least the offset and keeps
its band at least the vertical separation clear of every slot its conflicting peers announce:
above each peer's lowest (and so above its climbs and descents), and above or below each
other one.  So a drone crossing one that cruises 5 m higher
climbs past it with the separation, never into its altitude; a peer whose band is already
clear is no conflict at all (the comparison's bands say so).  With three or more drones a
drone can be Alice to one peer and Bob to another: each announces its new slots at once, and
a drone that must stay clear of them re-plans.

A run compares Alice's path as planned, so a raise of hers cannot undo the conflict it was
made for (the planned band still meets the peer: the raise stands while the conflict does),
but with each segment's band *reaching* as far as she flies it (:func:`reach`: the raise of
the segment and of its neighbours, whose legs climb to it and descend from it) -- so a run
also sees a peer her raises or their ramps come near.  A peer whose slots her reaches do not
come within the separation of, where the planned bands did not already (:func:`reaching`),
would get the same answer again: a raise of hers means a new run only with the peers it
comes near.  Raises keep clear of the slots of every peer that flies its own altitudes
(``keep_clear``: a conflict the next run would find anyway, avoided at once); a raised peer's
slots span its column from its cruise up, and keeping clear of those too made drones raised
for each other climb past each other in turn to the ceiling (four drones through one point:
+90 m).  Raises so go above the peers runs found in conflict and the peers not raised yet,
never above a peer only because it climbed for a third drone, and no two drones chase each
other: four drones through one point stacked three levels (+45 m) in every measured run
(``busy_four_eu868``, docs/benchmarks.md).

What a peer learns: which 5 m slots the drone occupies somewhere on its remaining path -- not
where, not which segment, not its altitude to better than 5 m (its beacon's current altitude
already says where it is now).  That is what choosing a clear altitude needs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from companion.errors import CompanionError

SLOT_M = 5.0
BASE_M = -1000.0  # slot 0 starts here (AMSL)
SLOTS = 32  # announced per beacon, from the lowest occupied; the last means "and above"
MAX_RAISE_M = 300.0


class NoClearAltitude(CompanionError):
    """No raise up to MAX_RAISE_M keeps the band clear of the peers' slots."""


@dataclass(frozen=True, slots=True)
class Slots:
    """Occupied altitude slots: bit i of ``mask`` is slot ``base + i``
    ([BASE_M + (base + i) SLOT_M, + SLOT_M) metres AMSL); bit 31 covers everything above."""

    base: int = 0
    mask: int = 0

    @classmethod
    def of(cls, bands: Iterable[tuple[float, float]]) -> Slots:
        """The slots the closed altitude bands (metres AMSL) touch."""
        spans = [
            (math.floor((lo - BASE_M) / SLOT_M), math.floor((hi - BASE_M) / SLOT_M))
            for lo, hi in bands
        ]
        if not spans:
            return cls()
        base = max(min(lo for lo, _ in spans), 0)
        mask = 0
        for lo, hi in spans:
            for slot in range(max(lo, base), hi + 1):
                mask |= 1 << min(slot - base, SLOTS - 1)
        return cls(min(base, 0xFFFF), mask)

    @property
    def top(self) -> int:
        """The highest occupied slot (-1: none)."""
        return self.base + self.mask.bit_length() - 1 if self.mask else -1

    def intervals(self) -> list[tuple[float, float]]:
        """The occupied altitudes (metres AMSL) as closed intervals, merged."""
        out: list[tuple[float, float]] = []
        for i in range(SLOTS):
            if not self.mask >> i & 1:
                continue
            low = BASE_M + (self.base + i) * SLOT_M
            high = math.inf if i == SLOTS - 1 else low + SLOT_M
            if out and out[-1][1] >= low:
                out[-1] = (out[-1][0], high)
            else:
                out.append((low, high))
        return out


def reach(raises: Mapping[int, float]) -> dict[int, float]:
    """Segment -> metres its band reaches past the plan as flown: the largest (by size) of
    its raise and its neighbours' -- a leg is a straight 3-D line, so the leg before a
    raised run climbs to it and the first one after descends from it
    (:mod:`companion.mission.planner`); an in-flight edit's inserted waypoint lies on the
    raised segment itself."""
    out: dict[int, float] = {}
    for k in {j + d for j, r in raises.items() if r for d in (-1, 0, 1) if j + d >= 0}:
        out[k] = max((raises.get(j, 0.0) for j in (k - 1, k, k + 1)), key=abs)
    return out


def reaching(
    bands: Mapping[int, tuple[float, float]],
    reaches: Mapping[int, float],
    slots: Slots,
    vertical_m: float,
) -> frozenset[tuple[int, float]]:
    """The reaches (segment, metres) that bring a segment within ``vertical_m`` of ``slots``
    where its planned band (``bands``) was not: a run against the drone announcing them must
    see them; against any other drone a reach changes nothing -- its band comes within the
    separation of no altitude the planned band did not."""
    spans = slots.intervals()
    out = set()
    for k, extra in reaches.items():
        if k not in bands or not extra:
            continue
        low, high = bands[k]
        if extra > 0:
            near = (high + vertical_m, high + extra + vertical_m)
        else:
            near = (low + extra - vertical_m, low - vertical_m)
        if any(bottom <= near[1] and top >= near[0] for bottom, top in spans):
            out.add((k, extra))
    return frozenset(out)


def clear_raise(
    band: tuple[float, float],
    peers: Iterable[Slots],
    offset_m: float,
    vertical_m: float,
    direction: float = 1.0,
    others: Iterable[Slots] = (),
    limit_m: float = MAX_RAISE_M,
) -> float:
    """The least raise (a multiple of SLOT_M, at least ``offset_m``, at most ``limit_m``;
    negative for ``direction`` -1) after which ``band`` is at least ``vertical_m`` clear of
    every conflicting peer's slots -- above its lowest occupied interval, above or below each
    other one -- and of every slot of ``others`` (peers it does not conflict with where it
    flies now: above or below)."""
    occupied = [(slots.intervals(), 1) for slots in peers]
    occupied += [(slots.intervals(), 0) for slots in others]
    steps = math.ceil(offset_m / SLOT_M)
    while steps * SLOT_M <= min(limit_m, MAX_RAISE_M) + 1e-9:
        delta = direction * steps * SLOT_M
        low, high = band[0] + delta, band[1] + delta
        if all(
            low >= top + vertical_m or (k >= first and high <= bottom - vertical_m)
            for spans, first in occupied
            for k, (bottom, top) in enumerate(spans)
        ):
            return delta
        steps += 1
    raise NoClearAltitude(
        f"no altitude within {min(limit_m, MAX_RAISE_M):.0f} m clears the peers' slots"
    )


def plan_raises(
    conflicts: Mapping[int, set[int]],
    precautions: Mapping[int, set[int]],
    slots: Mapping[int, Slots],
    bands: Mapping[int, tuple[float, float]],
    offset_m: float,
    vertical_m: float,
    direction: float = 1.0,
    keep_clear: Iterable[int] = (),
    headroom: Mapping[int, float] | None = None,
) -> tuple[dict[int, float], list[int]]:
    """Segment -> raise (metres) for the conflicts found and the precautions taken (peer ->
    segments): each clear of the slots of the peers it conflicts with (``slots``, peer ->
    announced), its band (``bands``: the segment's planned band, AMSL) raised, and clear of
    the slots of the peers in ``keep_clear`` too (peers not raised: a conflict the next
    run would find, avoided at once).  A precaution is a conflict until its result is in.

    ``headroom`` (segment -> metres up to the ceiling) bounds each raise: a segment no raise
    under it clears stays where it is and is returned among the unresolved -- the rest are
    still raised (an edit refused whole at the ceiling left every conflict unresolved); it
    is never raised into a peer kept clear of instead.  Returns (raises, unresolved
    segments)."""
    peers_of: dict[int, set[int]] = {}
    for table in (conflicts, precautions):
        for peer, segments in table.items():
            for segment in segments:
                peers_of.setdefault(segment, set()).add(peer)
    out: dict[int, float] = {}
    unresolved: list[int] = []
    for segment, peers in sorted(peers_of.items()):
        announced = [slots.get(peer, Slots()) for peer in peers]
        others = [slots[p] for p in keep_clear if p not in peers and p in slots]
        limit = MAX_RAISE_M if headroom is None else headroom.get(segment, MAX_RAISE_M)
        band = bands[segment]
        try:
            out[segment] = clear_raise(
                band, announced, offset_m, vertical_m, direction, others, limit
            )
        except NoClearAltitude:
            if headroom is None:
                raise
            unresolved.append(segment)
    return out, unresolved
