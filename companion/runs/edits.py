"""What the companion changes on its drone: altitude edits and precautions.

Conflicts (from Alice's runs) and precautions (from the fail-safe,
:mod:`companion.runs.guard`) become raises clear of the peers' altitude slots
(:func:`companion.mission.levels.plan_raises`) and an uploaded, read-back mission edit that
flies each raised segment at its raise from end to end
(:func:`companion.mission.planner.plan_edit`); a precaution may instead hold before a segment
until the result is in.

Raises climb up to the ceiling, or at most ``offset.max_levels`` offsets above the plan when
that is set (six drones through one point stacked five levels, +50 m, one on another).  A
conflict no raise that high clears is resolved by *time*: the drone holds before its first
such segment until a comparison says it may fly on.  While it holds, its windows are open
from now to the end (:meth:`companion.mission.own_flight.OwnFlight.keep_time`), so that
comparison is "may I leave now and come at any time after?": clear once the peer's
remaining path no longer comes near the held segments (it has passed).  The peer is asked
again ``HOLD_RECHECK_S`` after each result that still flags them.  Chosen as
deterministically as levels: only the pair's Alice learns of the conflict and holds.  Holds
that wait on one another in a ring would never end: a hold longer than ``MAX_HOLD_S`` gives
way to raises up to the ceiling for the rest of the flight, and what the ceiling cannot
clear is flown as planned (reported), not held for again.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from companion.context import Context
from companion.events import (
    EventKind,
    FixedSegments,
    Hold,
    PeerFailure,
    PeerNote,
    Problem,
    Uploaded,
)
from companion.mission.autopilot import AutopilotBase, AutopilotError
from companion.mission.flightpath import DO_JUMP
from companion.mission.items import MissionError, MissionItem
from companion.mission.levels import NoClearAltitude, plan_raises
from companion.mission.own_flight import OwnFlight, same_track
from companion.mission.planner import Edit, PlannerError, fixed_segments, plan_edit
from companion.neighbours.neighbourhood import Neighbourhood
from companion.neighbours.peers import Peer
from companion.runs.failsafe import Action

HOLD_RECHECK_S = 20.0  # holding for a conflict: the peer is asked again this long after a result
MAX_HOLD_S = 180.0  # a hold for conflicts this long: raises up to the ceiling instead


class Edits:
    """Raises, uploads and holds.  ``announce()``: our beacons should tell the new slots."""

    def __init__(
        self,
        ctx: Context,
        flight: OwnFlight,
        neighbourhood: Neighbourhood,
        autopilot: AutopilotBase,
        announce: Callable[[], None],
    ) -> None:
        self.ctx = ctx
        self.settings = ctx.settings
        self.flight = flight
        self.vehicle = flight.vehicle
        self.peers = neighbourhood.peers
        self.autopilot = autopilot
        self._announce = announce
        self.flagged: set[int] = set()  # segments in conflict at a verified edit, in the flight
        self.precaution: dict[int, set[int]] = {}  # peer -> segments climbed as a precaution
        self.holding: set[int] = set()  # peers we hold for
        # peer -> segments no raise within max_levels clears (conflicts or precautions): we
        # hold before them until a comparison clears them
        self.time_holds: dict[int, set[int]] = {}
        self.unbounded = False  # a hold lasted MAX_HOLD_S: raises go to the ceiling from now on

    def covers(self, node: int) -> bool:
        """A precaution for this peer stands (a climb, a hold, or one only reported)."""
        return node in self.precaution or node in self.holding

    async def take(self, node: int, action: Action, segments: list[int]) -> None:
        """The fail-safe's precaution for peer ``node``: climb over ``segments`` (levels
        chosen with the conflicts), hold before the first of them, or only note it."""
        if action is Action.OFF:
            self.precaution[node] = set()  # reported once; nothing flies differently
        elif action is Action.CLIMB:
            self.precaution[node] = set(segments)
            await self.replan(f"precaution for {node}")
        else:
            self.holding.add(node)
            self.ctx.spawn(self._hold_before(node, segments[0]), "hold")

    async def _hold_before(self, peer: int, segment: int) -> None:
        """Pause the mission once the vehicle reaches the start of ``segment`` (at once if it
        flies it already)."""
        vs = self.flight.path.vertices
        end = vs[min(segment + 1, len(vs) - 1)]
        gate = min(end.items, default=0)  # the segment is flown once its end item is current
        while peer in self.holding and self.vehicle.current_item < gate:
            await self.ctx.clock.sleep(0.5)
        if peer not in self.holding:
            return
        try:
            await self.autopilot.pause()
            self.ctx.record(EventKind.HOLD, Hold(peer=peer, before_segment=segment))
        except AutopilotError as exc:
            self.ctx.record(EventKind.HOLD_FAILED, PeerFailure(peer=peer, error=str(exc)))
            return
        if peer in self.time_holds:
            self.ctx.spawn(self._hold_limit(), "hold limit")

    async def _hold_limit(self) -> None:
        """Holds for conflicts that wait on one another (A for B, B for C, C for A) never
        end: after MAX_HOLD_S the raises go up to the ceiling instead, and no conflict is
        held for again."""
        await self.ctx.clock.sleep(MAX_HOLD_S)
        if self.time_holds and self.vehicle.held and not self.unbounded:
            self.unbounded = True
            self.ctx.record(
                EventKind.PLAN_FAILED,
                Problem(error=f"held {MAX_HOLD_S:g} s for {sorted(self.time_holds)}: raises "
                        "go up to the ceiling from now on"),
            )  # fmt: skip
            await self.replan("a hold lasted too long")

    async def release(self, node: int) -> None:
        """The result is in: precautions for this peer end (a hold for a conflict with it
        ends when a comparison clears the held segments: :meth:`_hold_for`)."""
        self.precaution.pop(node, None)
        if node in self.time_holds:
            return
        await self._end_hold(node)

    async def _end_hold(self, node: int) -> None:
        """We no longer hold for ``node``: fly on unless we hold for another peer."""
        if node not in self.holding:
            return
        self.holding.discard(node)
        if self.holding:
            return
        try:
            await self.autopilot.resume()
            self.ctx.record(EventKind.RESUMED, PeerNote(peer=node))
        except AutopilotError as exc:
            self.ctx.record(EventKind.RESUME_FAILED, PeerFailure(peer=node, error=str(exc)))

    def slots_heard(self, peer: Peer, new_peer: bool) -> None:
        """A peer announced new altitude slots: raises for it (a conflict, a precaution)
        clear its new slots, and ours keep clear of those of a peer that flies its own
        altitudes (:meth:`_keeps_clear_of`).  A peer heard for the first time is news to
        both."""
        raised = bool(self.flight.ahead(self.flight.raises))
        ours = bool(peer.conflicts) or peer.node in self.precaution
        if ours or (raised and (new_peer or self._keeps_clear_of(peer))):
            self.ctx.spawn(self.replan(f"peer {peer.node} announced altitude slots"), "replan")

    def _keeps_clear_of(self, peer: Peer) -> bool:
        """Whether our raises keep clear of the altitude slots of ``peer`` even where we do
        not conflict with it: of a peer that flies its own altitudes.  Not needed -- our
        runs compare our bands as far as our raises take them
        (:meth:`OwnFlight.reaches`), a peer's compare its own against them -- but a
        conflict avoided needs no run.  Not of a raised peer: its slots span its column
        from its cruise up, and keeping clear of those made drones raised for each other
        climb past each other in turn to the ceiling (:mod:`companion.mission.levels`)."""
        return not peer.raised

    async def replan(self, why: str) -> None:
        """Upload the raises the conflicts and precautions call for, if they changed."""
        async with self.flight.editing:
            clear_of = sorted(n for n, p in self.peers.items() if self._keeps_clear_of(p))
            planned = self._raises(clear_of)
            if planned is None:
                return
            raises, unresolved = planned
            await self._hold_for(unresolved)
            if self.flight.ahead(raises) == self.flight.ahead(self.flight.raises):
                return
            try:
                edit = plan_edit(
                    self.flight.original,
                    raises,
                    self.settings.offset,
                    path=self.flight.path,
                    vehicle=self.flight.edit_vehicle(),
                )
            except PlannerError as exc:
                self.ctx.record(EventKind.PLAN_FAILED, Problem(error=str(exc)))
                return
            fixed = fixed_segments(self.flight.path, raises)
            if fixed:  # e.g. the last leg into a landing: its end may not move
                self.ctx.record(EventKind.FIXED_SEGMENTS, FixedSegments(segments=fixed, why=why))
            try:
                new, mark, sent_at = await self._upload(edit)
            except (AutopilotError, MissionError) as exc:
                self.ctx.record(EventKind.UPLOAD_FAILED, Problem(error=str(exc)))
                return
            self.flight.edited(new, raises, Edit(new, edit.origin, edit.inserted), mark, sent_at)
            self._announce()  # peers keep clear of our slots: tell them now, not in minutes
            # (every segment flagged at a verified edit: a later run from where the drone is,
            # past the conflict, clears it and the raise may be flown back down)
            self.flagged |= {k for p in self.peers.values() for k in p.conflicts}
            self.ctx.record(
                EventKind.UPLOADED,
                Uploaded(
                    flagged=sorted(raises),
                    raises={str(k): v for k, v in sorted(raises.items())},
                    verified=True,
                    offset_m=self.settings.offset.delta,
                    inserted=edit.inserted,
                    clear_of=clear_of,  # peers whose altitudes the raises keep clear of as well
                    why=why,
                ),
            )

    async def _hold_for(self, unresolved: list[int]) -> None:
        """Hold for each peer whose conflicts (or precautions) include segments no raise
        within max_levels clears, before the first of them still ahead; end the holds of
        peers whose such segments a comparison cleared; while held, ask the peers held for
        again HOLD_RECHECK_S after each result."""
        start = self.flight.remaining_path()[0]
        wanted: dict[int, set[int]] = {}
        if self.settings.offset.max_levels is not None and not self.unbounded:
            for node, peer in self.peers.items():
                segments = (peer.conflicts | self.precaution.get(node, set())) & set(unresolved)
                if ahead := {k for k in segments if k >= start}:
                    wanted[node] = ahead
        for node in [n for n in self.time_holds if n not in wanted]:
            del self.time_holds[node]
            if node in self.peers:
                self.peers[node].recheck_at = math.inf
            await self._end_hold(node)
        now = self.ctx.clock.now()
        for node, segments in wanted.items():
            peer = self.peers[node]
            if node not in self.time_holds and node not in self.holding:
                self.holding.add(node)
                self.ctx.spawn(self._hold_before(node, min(segments)), "hold")
            self.time_holds[node] = segments
            if self.vehicle.held and peer.conflicts & segments and math.isinf(peer.recheck_at):
                peer.recheck_at = now + HOLD_RECHECK_S

    def _raises(self, clear_of: list[int]) -> tuple[dict[int, float], list[int]] | None:
        """The raises the conflicts and precautions call for, and the segments none within
        max_levels (or under the ceiling) clears (None: no clear altitude, recorded).  A
        raise only grows while its conflict stands: a peer whose announced slots shrink (it
        flew on, it landed) is no reason for another edit in flight."""
        offset = self.settings.offset
        bands = self.flight.planned_bands()
        # up to the ceiling (metres above home): the planned top of each band is its top
        # less our altitude error; and no more than max_levels offsets (then: a hold)
        ceiling = self.flight.home_deg()[2] + offset.max_altitude_m
        error = self.settings.separation.tolerance.altitude_m
        cap = math.inf if self.unbounded else offset.max_raise_m
        up = offset.direction == "up"
        headroom = {
            k: min(ceiling - (top - error) if up else math.inf, cap)
            for k, (_, top) in bands.items()
        }
        try:
            raises, unresolved = plan_raises(
                {node: p.conflicts for node, p in self.peers.items()},
                self.precaution,
                {node: p.beacon.slots for node, p in self.peers.items()},
                bands,
                offset.offset_m,
                self.settings.separation.vertical_m,
                1.0 if up else -1.0,
                keep_clear=clear_of,
                headroom=headroom if up or math.isfinite(cap) else None,
            )
        except NoClearAltitude as exc:
            self.ctx.record(EventKind.PLAN_FAILED, Problem(error=str(exc)))
            return None
        if unresolved and (offset.max_levels is None or self.unbounded):
            error_text = (
                f"segments {unresolved}: no altitude under the ceiling "
                f"({offset.max_altitude_m:g} m) clears the peers they conflict with"
            )
            self.ctx.record(EventKind.PLAN_FAILED, Problem(error=error_text))
        held = self.flight.raises
        return {k: max(v, held.get(k, v), key=abs) for k, v in raises.items()}, unresolved

    async def _upload(self, edit: Edit) -> tuple[list[MissionItem], int, float]:
        """Upload ``edit`` (read back by the autopilot): the items the vehicle now holds, the
        one marked current and when the upload began.  The edit is built on what the
        vehicle holds now and keeps the item it is flying: PX4 restarts a mission at the item
        an upload marks current."""
        held = await self.autopilot.download()
        before = self.flight.edit
        if not same_track(held, before.items if before is not None else self.flight.original):
            raise AutopilotError("the vehicle's mission changed since the start")
        current = max(
            self.vehicle.current_item, next((i for i, it in enumerate(held) if it.current), 0)
        )
        current = min(current, len(held) - 1)
        original = before.origin[current] if before is not None else current
        mark = edit.inserted if edit.inserted is not None else edit.index_of(original)
        new = []
        for i, planned in enumerate(edit.items):
            if i == edit.inserted:
                new.append(planned.replace(current=int(i == mark)))
                continue
            source = before.index_of(edit.origin[i]) if before is not None else edit.origin[i]
            new.append(held[source].replace(seq=i, z=planned.z, current=int(i == mark)))
        new = [
            it.replace(param1=edit.items[i].param1) if it.command == DO_JUMP else it
            for i, it in enumerate(new)
        ]  # jump targets as the edit numbers them
        sent_at = self.ctx.clock.now()
        await self.autopilot.replace_mission(new, held)
        return new, mark, sent_at
