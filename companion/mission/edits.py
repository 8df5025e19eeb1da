"""What the companion changes on its drone: altitude edits and precautions.

Conflicts (from Alice's runs) and precautions become raises clear of the peers' altitude
slots (:func:`companion.mission.levels.plan_raises`) and an uploaded, read-back mission edit that
flies each raised segment at its raise from end to end
(:func:`companion.mission.planner.plan_edit`). The fail-safe (:mod:`companion.runs.failsafe`)
watches every run under way and every peer still waiting for one: when a result could come too late
it climbs over, or holds before, the segments within the peer's reach until the result is in.
"""

from __future__ import annotations

import math

from companion.app.core import CompanionCore, same_track
from companion.events import (
    EventKind,
    FixedSegments,
    Hold,
    PeerFailure,
    PeerNote,
    Precaution,
    Problem,
    Uploaded,
)
from companion.mission.autopilot import AutopilotError
from companion.mission.flightpath import DO_JUMP
from companion.mission.items import MissionError
from companion.mission.levels import NoClearAltitude, plan_raises
from companion.mission.planner import Edit, PlannerError, fixed_segments, plan_edit
from companion.mission.planner import Vehicle as PlanVehicle
from companion.mission.schedule import Vehicle, predict
from companion.neighbours.peers import Peer
from companion.runs.failsafe import Action, at_risk, too_late
from protocol.geo.grid import GridSpec
from protocol.intersection import Alice
from protocol.run import DEFAULT_LIMITS


class Edits(CompanionCore):
    """Altitude edits, precautions and the fail-safe's watch."""

    async def _watch(
        self,
        peer: Peer,
        alice: Alice,
        grid: GridSpec,
        needed: float,
    ) -> None:
        """While a run is under way: act as soon as its result could come too late.  Until
        Bob's first reply tells his size the estimate is that of the smallest Bob (Alice's
        own size would cry wolf when Bob's path is short: runs are sized m x n); then it is
        the rest of the real m x n run from that moment; past it, as long as the overrun.
        A wait for our duty-cycle budget counts when even a lossless run could not escape it,
        or when it comes (a frame is queued for the budget): a run whose share fits the
        budget only if few frames are lost is watched, not given up at once -- the margin
        still leaves time to act when the wait comes."""
        deadline = self.clock.now() + needed
        self._running = (peer.node, deadline)
        sized = False
        while True:
            await self.clock.sleep(2.0)
            if not sized and alice.n is not None:
                sized = True  # messages 1 and 2 (hello, offer) are behind us
                rest = self._seconds(alice.m, grid, fresh=False, n=alice.n, skip=2, stall_loss=0.0)
                deadline = self.clock.now() + rest
                self._running = (peer.node, deadline)
            # Overdue (losses, a silent peer): the estimate has failed; expect as long again
            # as it has overrun, so the fail-safe does not wait for the last seconds.
            left = max(abs(deadline - self.clock.now()), 2.0) + self.endpoint.budget_wait()
            if too_late(left, self._urgency(peer), self.settings.failsafe):
                await self._precaution(peer, left, self._urgency(peer))
                return

    async def _guard(self) -> None:
        """The fail-safe for peers still waiting for their run (one run at a time on the
        radio, a retry after a failure): act when even the smallest run, started once ours
        on the air ends, would bring the result too late.  The peer a run is under way with
        has its own watch."""
        while True:
            await self.clock.sleep(2.0)
            if self.vehicle.on_ground or not self.peers:
                continue
            now = self.clock.now()
            running, ends = self._running or (None, now)
            for peer in list(self.peers.values()):
                if peer.node == running or peer.node in self.precaution or not self._pending(peer):
                    continue
                _, path = self._remaining_path()
                if len(path) < 2:
                    break
                first = self._near(path, 1)  # the least a run compares
                needed = max(ends - now, 0.0) + self._seconds(
                    DEFAULT_LIMITS.public_size(len(first) - 1),
                    self._grid(first),
                    fresh=peer.node not in self.holder_setups,
                    n=1,
                )
                meet = self._urgency(peer)
                if too_late(needed, meet, self.settings.failsafe):
                    await self._precaution(peer, needed, meet, waiting=True)

    async def _precaution(
        self, peer: Peer, needed: float, meet: float, *, waiting: bool = False
    ) -> None:
        """Climb over (or hold before) the segments both drones may reach before the result.
        The path is what is left to fly *now*: a run's path starts where the drone was when
        it began, and distances from here along legs already flown would come out wrong."""
        settings = self.settings.failsafe
        if peer.node in self.precaution or peer.node in self._holding or self.vehicle.on_ground:
            return  # (on the ground the drone waits for its comparisons anyway)
        start, path = self._remaining_path()
        speed = max(self.vehicle.speed_m_s, self.settings.cruise_m_s)
        schedule = self._schedule(self.original, self.path, start, self.original_current)
        tolerance = self.settings.separation.tolerance
        windows = [schedule.window(k, tolerance) for k in range(start, start + len(path) - 1)]
        # A segment a run found in conflict with this peer and that we fly raised for it
        # (verified upload) needs no precaution while it is compared again (the peer or we
        # were retimed: the comparison restarts, the raise stands until its result).
        decided = self._decided(peer) | {k for k in peer.conflicts if self.raises.get(k)}
        risky = at_risk(
            path, start, self.vehicle.here(), speed, peer.position, self._peer_speed(peer), needed,
            settings, decided, peer_age_s=peer.position_age(self.clock.now()),
            entered=[w[0] for w in windows], left=[w[1] for w in windows],
        )  # fmt: skip
        if not risky:
            return
        self.record(
            EventKind.PRECAUTIONARY,
            Precaution(
                peer=peer.node,
                action=settings.action.value,
                segments=risky,
                first_segment=start,
                needed_s=round(needed, 1),
                time_to_meet_s=round(meet, 1) if math.isfinite(meet) else None,
                waiting=waiting,
            ),
        )
        if settings.action is Action.OFF:
            self.precaution[peer.node] = set()  # reported once; nothing flies differently
            return
        if settings.action is Action.CLIMB:
            self.precaution[peer.node] = set(risky)  # levels chosen with the conflicts
            await self._replan(f"precaution for {peer.node}")
        else:
            self._holding.add(peer.node)
            self._spawn(self._hold_before(peer.node, risky[0]))

    async def _hold_before(self, peer: int, segment: int) -> None:
        """Pause the mission once the vehicle reaches the start of ``segment``."""
        vs = self.path.vertices
        end = vs[min(segment + 1, len(vs) - 1)]
        gate = min(end.items, default=0)  # the segment is flown once its end item is current
        while peer in self._holding and self.vehicle.current_item < gate:
            await self.clock.sleep(0.5)
        if peer not in self._holding:
            return
        try:
            await self.autopilot.pause()
            self.record(EventKind.HOLD, Hold(peer=peer, before_segment=segment))
        except AutopilotError as exc:
            self.record(EventKind.HOLD_FAILED, PeerFailure(peer=peer, error=str(exc)))

    async def _release(self, peer: Peer) -> None:
        """The result is in: precautions for this peer end."""
        self.precaution.pop(peer.node, None)
        if peer.node in self._holding:
            self._holding.discard(peer.node)
            if not self._holding:
                try:
                    await self.autopilot.resume()
                    self.record(EventKind.RESUMED, PeerNote(peer=peer.node))
                except AutopilotError as exc:
                    self.record(
                        EventKind.RESUME_FAILED, PeerFailure(peer=peer.node, error=str(exc))
                    )

    def _planned_bands(self) -> dict[int, tuple[float, float]]:
        """Every segment's band off the ground as planned (the original mission flown from
        the ground), widened by our altitude error: what a raise starts from."""
        if self._planned is None:
            self._planned = predict(
                self.path,
                self.original,
                self._home_deg(),
                0,
                Vehicle(*self._home_deg()[:2], 0.0, 0.0, 1 if self.settings.ardupilot else 0, True),
                self.kinematics,
                home_is_item0=self.settings.ardupilot,
            )
        tolerance = self.settings.separation.tolerance
        return {k: self._planned.cruise(k, tolerance) for k in range(self.path.segments)}

    def _ahead(self, raises: dict[int, float]) -> dict[int, float]:
        """The raises of the segments not flown yet (all of them before take-off)."""
        first, _ = self._remaining_path()
        return {k: v for k, v in raises.items() if k >= first}

    def _edit_vehicle(self) -> PlanVehicle:
        lat, lon, amsl = self.vehicle.position
        segment = None if self.vehicle.on_ground else self.path.start_at(self.original_current)
        lead = max(self.vehicle.speed_m_s, 1.0) / self.kinematics.climb_m_s
        return PlanVehicle(segment, lat, lon, self.vehicle.relative_alt, amsl, lead)

    def _keeps_clear_of(self, peer: Peer) -> bool:
        """Whether our raises keep clear of the altitude slots of ``peer`` even where we do
        not conflict with it (a run compared the altitudes we fly without raises): of a peer
        that flies its own altitudes, and of a lower node's.  Of two drones that raised into
        each other's slots the higher node moves (it hears the lower one's new slots and
        re-plans), so two never climb past each other in turn."""
        return not peer.raised or peer.node < self.settings.node

    async def _replan(self, why: str) -> None:
        """Upload the raises the conflicts and precautions call for, if they changed."""
        async with self._edit_lock:
            offset = self.settings.offset
            clear_of = sorted(n for n, p in self.peers.items() if self._keeps_clear_of(p))
            try:
                raises = plan_raises(
                    {node: p.conflicts for node, p in self.peers.items()},
                    self.precaution,
                    {node: p.beacon.slots for node, p in self.peers.items()},
                    self._planned_bands(),
                    offset.offset_m,
                    self.settings.separation.vertical_m,
                    1.0 if offset.direction == "up" else -1.0,
                    keep_clear=clear_of,
                )
            except NoClearAltitude as exc:
                self.record(EventKind.PLAN_FAILED, Problem(error=str(exc)))
                return
            # A raise only grows while its conflict stands: a peer whose announced slots
            # shrink (it flew on, it landed) is no reason for another edit in flight.
            raises = {k: max(v, self.raises.get(k, v), key=abs) for k, v in raises.items()}
            if self._ahead(raises) == self._ahead(self.raises):
                return
            try:
                edit = plan_edit(
                    self.original, raises, offset, path=self.path, vehicle=self._edit_vehicle()
                )
            except PlannerError as exc:
                self.record(EventKind.PLAN_FAILED, Problem(error=str(exc)))
                return
            fixed = fixed_segments(self.path, raises)
            if fixed:  # e.g. the last leg into a landing: its end may not move
                self.record(EventKind.FIXED_SEGMENTS, FixedSegments(segments=fixed, why=why))
            try:
                # The edit is built on what the vehicle holds now and keeps the item it is
                # flying: PX4 restarts a mission at the item an upload marks current.
                held = await self.autopilot.download()
                before = self.edit.items if self.edit is not None else self.original
                if not same_track(held, before):
                    raise AutopilotError("the vehicle's mission changed since the start")
                current = max(
                    self.vehicle.current_item,
                    next((i for i, it in enumerate(held) if it.current), 0),
                )
                current = min(current, len(held) - 1)
                original = self.edit.origin[current] if self.edit is not None else current
                mark = edit.inserted if edit.inserted is not None else edit.index_of(original)
                new = []
                for i, planned in enumerate(edit.items):
                    if i == edit.inserted:
                        new.append(planned.replace(current=int(i == mark)))
                        continue
                    source = self.edit.index_of(edit.origin[i]) if self.edit else edit.origin[i]
                    new.append(held[source].replace(seq=i, z=planned.z, current=int(i == mark)))
                new = [
                    it.replace(param1=edit.items[i].param1) if it.command == DO_JUMP else it
                    for i, it in enumerate(new)
                ]  # jump targets as the edit numbers them
                sent_at = self.clock.now()
                await self.autopilot.replace_mission(new, held)
            except (AutopilotError, MissionError) as exc:
                self.record(EventKind.UPLOAD_FAILED, Problem(error=str(exc)))
                return
            self.mission, self.raises = new, raises
            # Where the vehicle flies on: what it reported since the upload, or the item
            # the upload marked (PX4 goes on from there; its report may not have come yet).
            seen, total, when = self._progress_seen
            self.vehicle.current_item = seen if when >= sent_at and total == len(new) else mark
            self.edit = Edit(new, edit.origin, edit.inserted)
            self.sender.announce()  # peers keep clear of our slots: tell them now, not in
            # minutes (a duty-cycled beacon interval)
            self.flagged = {k for p in self.peers.values() for k in p.conflicts}
            self.record(
                EventKind.UPLOADED,
                Uploaded(
                    flagged=sorted(raises),
                    raises={str(k): v for k, v in sorted(raises.items())},
                    verified=True,
                    offset_m=offset.delta,
                    inserted=edit.inserted,
                    clear_of=clear_of,  # peers whose altitudes the raises keep clear of as well
                    why=why,
                ),
            )
