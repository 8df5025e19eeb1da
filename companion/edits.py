"""What the companion changes on its drone: altitude edits and precautions.

Conflicts (from Alice's runs) and precautions become altitude levels
(:func:`companion.levels.plan_levels`) and an uploaded, read-back mission edit
(:func:`companion.planner.plan_offsets`).  The fail-safe (:mod:`companion.failsafe`) watches
every run under way and every peer still waiting for one: when a result could come too late
it climbs over, or holds before, the segments within the peer's reach until the result is in.
"""

from __future__ import annotations

import math

from protocol.grid import GridSpec
from protocol.intersection import Alice, Limits

from .autopilot import AutopilotError
from .core import CompanionCore, same_track
from .events import EventKind
from .failsafe import Action, at_risk, too_late
from .levels import levels_mask, plan_levels
from .mission import MissionError
from .peers import Peer
from .planner import PlannerError, fixed_segments, plan_offsets


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
        the rest of the real m x n run from that moment; past it, as long as the overrun."""
        deadline = self.clock.now() + needed
        self._running = (peer.node, deadline)
        sized = False
        while True:
            await self.clock.sleep(2.0)
            if not sized and alice.n is not None:
                sized = True  # messages 1 and 2 (hello, offer) are behind us
                rest = self._seconds(alice.m, grid, fresh=False, n=alice.n, skip=2)
                deadline = self.clock.now() + rest
                self._running = (peer.node, deadline)
            # Overdue (losses, a silent peer): the estimate has failed; expect as long again
            # as it has overrun, so the fail-safe does not wait for the last seconds.
            left = max(abs(deadline - self.clock.now()), 2.0)
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
            if self.on_ground or not self.peers:
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
                    Limits().padded(len(first) - 1),
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
        if peer.node in self.precaution or peer.node in self._holding or self.on_ground:
            return  # (on the ground the drone waits for its comparisons anyway)
        start, path = self._remaining_path()
        speed = max(self.speed_m_s, self.settings.cruise_m_s)
        risky = at_risk(
            path, start, self._here(), speed, peer.position, self._peer_speed(peer), needed,
            settings, peer.covered, peer_age_s=self._silent_for(peer),
        )  # fmt: skip
        if not risky:
            return
        self.record(
            EventKind.PRECAUTIONARY,
            peer=peer.node,
            action=settings.action.value,
            segments=risky,
            first_segment=start,
            needed_s=round(needed, 1),
            time_to_meet_s=round(meet, 1) if math.isfinite(meet) else None,
            waiting=waiting,  # no run under way with this peer yet (queued, or a retry)
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
        while peer in self._holding and self.current_item < gate:
            await self.clock.sleep(0.5)
        if peer not in self._holding:
            return
        try:
            await self.autopilot.pause()
            self.record(EventKind.HOLD, peer=peer, before_segment=segment)
        except AutopilotError as exc:
            self.record(EventKind.HOLD_FAILED, peer=peer, error=str(exc))

    async def _release(self, peer: Peer) -> None:
        """The result is in: precautions for this peer end."""
        self.precaution.pop(peer.node, None)
        if peer.node in self._holding:
            self._holding.discard(peer.node)
            if not self._holding:
                try:
                    await self.autopilot.resume()
                    self.record(EventKind.RESUMED, peer=peer.node)
                except AutopilotError as exc:
                    self.record(EventKind.RESUME_FAILED, peer=peer.node, error=str(exc))

    async def _replan(self, why: str) -> None:
        """Upload the altitude levels the conflicts and precautions call for, if they changed."""
        async with self._edit_lock:
            levels = plan_levels(
                {node: p.conflicts for node, p in self.peers.items()},
                self.precaution,
                {node: p.beacon.levels for node, p in self.peers.items()},
            )
            if levels == self.levels:
                return
            try:
                planned = plan_offsets(self.original, levels, self.settings.offset, path=self.path)
            except PlannerError as exc:
                self.record(EventKind.PLAN_FAILED, error=str(exc))
                return
            fixed = fixed_segments(self.path, levels)
            if fixed:  # e.g. the launch leg to a take-off point: nothing there may move
                self.record(EventKind.FIXED_SEGMENTS, segments=fixed, why=why)
            try:
                # The edit is built on what the vehicle holds now and keeps the item it is
                # flying: PX4 restarts a mission at the item an upload marks current.
                held = await self.autopilot.download()
                if not same_track(held, self.original):
                    raise AutopilotError("the vehicle's mission changed since the start")
                current = max(
                    self.current_item, next((i for i, it in enumerate(held) if it.current), 0)
                )
                current = min(current, len(held) - 1)
                new = [
                    h.replace(z=p.z, current=int(i == current))
                    for i, (h, p) in enumerate(zip(held, planned, strict=True))
                ]
                await self.autopilot.replace_mission(new, held)
            except (AutopilotError, MissionError) as exc:
                self.record(EventKind.UPLOAD_FAILED, error=str(exc))
                return
            announce = levels_mask(levels) != levels_mask(self.levels)
            self.mission, self.levels = new, levels
            if announce:  # peers choose their levels around ours: tell them now, not in
                self._beacon_now.set()  # minutes (a duty-cycled beacon interval)
            self.flagged = {k for p in self.peers.values() for k in p.conflicts}
            self.record(
                EventKind.UPLOADED,
                flagged=sorted(levels),
                levels={str(k): v for k, v in sorted(levels.items())},
                verified=True,
                offset_m=self.settings.offset.delta,
                why=why,
            )
