"""The companion process: beacons, peers, private comparisons and altitude edits.

One :class:`Companion` per drone, beside its autopilot.  It beacons its coarse position; when
it hears a peer within the initiation range, the role rule
(:func:`companion.neighbours.beacon.alice_of`) picks exactly one of the two as Alice.  Alice
compares the part of her mission still to fly with the peer's through the private protocol over the
radio; the peer (Bob) answers with the part of *his* mission still to fly and learns nothing.
Alice flies her conflicting segments at an altitude level (:mod:`companion.mission.levels`),
uploads the edit and reads it back.

In flight, what can be reached soon is compared first: a *near* run on the next
``lookahead_s`` seconds of both paths, then the *full* run on the rest.  The most urgent peer
(the one that could be here first) is served first.  Before and during every run Alice checks
that the result can arrive in time (:mod:`companion.runs.failsafe`); if not, she takes the
precautionary action (climb over, or hold before, the segments within the peer's reach) until
the result is in.  The OT setup with each peer is made once and cached.  Runs per peer are
limited (probing mitigation); failures are recorded, leave the mission as it was, and never
stop the process from serving other peers: nothing raises out of a run.

:class:`Companion` is assembled from one part per concept on a shared core
(:mod:`companion.app.core`): :mod:`companion.neighbours.beaconing`, :mod:`companion.runs.alice`,
:mod:`companion.runs.bob` and :mod:`companion.mission.edits`; this module starts and stops it and
follows the vehicle through its autopilot's telemetry
(:class:`companion.mission.autopilot.AutopilotBase`: MAVSDK, or a mock vehicle in the same process).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time

from companion.app import logs
from companion.app.core import TIMING_EVERY_S, CompanionSettings, Credentials
from companion.events import EventKind, MissionRead, Problem
from companion.mission.flightpath import flight_path
from companion.mission.items import MissionError
from companion.neighbours.beaconing import Beaconing
from companion.runs.alice import AliceRuns
from companion.runs.bob import BobAnswers

__all__ = ["Companion", "CompanionSettings", "Credentials"]

log = logging.getLogger("companion")
EDIT_GRACE_S = 20.0  # an upload and its read-backs take seconds over a real link
POSITION_RATE_HZ = 5.0  # telemetry position updates asked of the autopilot
AUTOPILOT_SILENT_S = 5.0  # no position from the autopilot this long (real s): a warning


class Companion(AliceRuns, Beaconing, BobAnswers):
    """One drone's companion: ``await Companion(...).start()``, ``await stop()``."""

    async def start(self) -> None:
        self.epoch = self.clock.now()
        self.original = await self.autopilot.download()
        self.mission = list(self.original)
        if not self.settings.ardupilot:  # ArduPilot's home is item 0 of the mission
            self.home = await self.autopilot.home()
        home = None if self.home is None else self.home[:2]
        try:
            self.path = flight_path(self.mission, home, ardupilot=self.settings.ardupilot)
        except MissionError as exc:  # e.g. a DO_JUMP to nowhere: fly, but compare nothing
            self.record(EventKind.MISSION_INVALID, Problem(error=str(exc)))
        self.record(
            EventKind.MISSION,
            MissionRead(
                items=len(self.mission),
                segments=self.path.segments,
                home=self.home is not None or self.settings.ardupilot,
            ),
        )
        await self.endpoint.start()
        for name, work in (
            ("telemetry", self._telemetry),
            ("progress", self._progress),
            ("armed", self._armed),
            ("flight mode", self._flight_mode),
            ("autopilot watch", self._autopilot_watch),
            ("guard", self._guard),
            ("timing", self._timing_watch),
        ):
            self._spawn(work(), name)
        self.start_radio()

    def start_radio(self) -> None:
        """The parts on the radio: our beacons out (certificates, positions), theirs in,
        answers as Bob, our runs as Alice (the endpoint started)."""
        self._spawn(self.sender.certificates(), "certificates")
        self._spawn(self.sender.positions(self._own_beacon, self._on_air), "beacons")
        self._spawn(self._listen(), "listen")
        self._spawn(self._serve(), "serve")
        self._spawn(self._alice_loop(), "alice")

    async def stop(self) -> None:
        """Cancel every task and close the radio and the store.  A mission edit under way is
        let finish first (bounded): cut between upload and read-back it would leave the
        vehicle holding a mission the companion never recorded."""
        editing = False
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._edit_lock.acquire(), EDIT_GRACE_S)
            editing = True
        tasks = list(self._children)
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                try:  # bounded: a stop never hangs on one task
                    await asyncio.wait_for(asyncio.shield(task), 5.0)
                except TimeoutError:
                    log.warning("node %d: task %s did not stop", self.settings.node, task)
                except Exception as exc:  # a task that failed has nothing left to stop
                    log.warning("node %d: task %s ended with %r", self.settings.node, task, exc)
        if editing:
            self._edit_lock.release()
        await self.endpoint.close()
        self.store.close()

    async def _telemetry(self) -> None:
        async for p in self.autopilot.positions(POSITION_RATE_HZ):
            now = self.clock.now()
            if self.vehicle.moved(p.lat_deg, p.lon_deg, p.amsl_m, p.relative_m, now):
                self.sender.announce()  # taking off: announce it
            self._note_position()

    async def _armed(self) -> None:
        async for armed in self.autopilot.armed_states():
            if self.vehicle.arming(armed):
                self.sender.announce()  # taking off: announce it

    async def _flight_mode(self) -> None:
        """Is the vehicle holding in the air (PX4 AUTO.LOITER, ArduPilot LOITER: paused by
        an operator or by us, or its mission over)?  Then when it flies on is unknown."""
        async for held in self.autopilot.holding_states():
            self.vehicle.held = held

    async def _autopilot_watch(self) -> None:
        """Warn when the autopilot's position stops coming (real seconds: MAVLink streams run
        in real time whatever the link's clock), and again when it is back."""
        silent = False
        while True:
            await asyncio.sleep(1.0)
            gap = time.monotonic() - self.vehicle.heard_at
            if gap >= AUTOPILOT_SILENT_S and not silent:
                silent = True
                logs.event(
                    log,
                    logging.WARNING,
                    "autopilot_silent",
                    f"node {self.settings.node}: no position from the autopilot for {gap:.0f} s",
                    url=self.settings.autopilot_url,
                )
            elif gap < AUTOPILOT_SILENT_S and silent:
                silent = False
                log.info("node %d: the autopilot's position is back", self.settings.node)

    async def _timing_watch(self) -> None:
        """Every few seconds: is the vehicle still within its windows?  (:meth:`_keep_time`)"""
        while True:
            await self.clock.sleep(TIMING_EVERY_S)
            self._keep_time()

    async def _progress(self) -> None:
        async for current, total in self.autopilot.progress():
            self._progress_seen = (current, total, self.clock.now())
            if total == len(self.mission) or not self._edit_lock.locked():
                self.vehicle.current_item = current
            # (else an edit is being uploaded: the vehicle numbers the items of the new
            # mission, and the companion holds the old one until the read-back is done)
