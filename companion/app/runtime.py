"""The companion process: beacons, peers, private comparisons and altitude edits.

One :class:`Companion` per drone, beside its autopilot.  It beacons its coarse position; when
it hears a peer within the initiation range, the role rule
(:func:`companion.neighbours.beacon.alice_of`) picks exactly one of the two as Alice.  Alice
compares the part of her mission still to fly with the peer's through the private protocol
over the radio; the peer (Bob) answers with the part of *his* mission still to fly and learns
nothing.  Alice flies her conflicting segments at an altitude level
(:mod:`companion.mission.levels`), uploads the edit and reads it back.

In flight, what can be reached soon is compared first: a *near* run on the next
``lookahead_s`` seconds of both paths, then the *full* run on the rest.  The most urgent peer
(the one that could be here first) is served first.  Before and during every run the
fail-safe checks that the result can arrive in time (:mod:`companion.runs.guard`); if not, it
takes the precautionary action (climb over, or hold before, the segments within the peer's
reach) until the result is in.  The OT setup with each peer is made once and cached.  Runs
per peer are limited (probing mitigation); failures are recorded, leave the mission as it
was, and never stop the process from serving other peers: nothing raises out of a run.

:class:`Companion` wires components that own their state (docs/architecture.md):

- :class:`~companion.mission.vehicle.VehicleState` -- what the telemetry says;
- :class:`~companion.mission.own_flight.OwnFlight` -- our mission, its schedule, keeping to it;
- :class:`~companion.neighbours.sender.BeaconSender` and
  :class:`~companion.neighbours.neighbourhood.Neighbourhood` -- beacons out and in, the peers;
- :class:`~companion.runs.alice.AliceRuns`, :class:`~companion.runs.bob.BobAnswers` -- runs
  as Alice and answers as Bob, taking turns on the :class:`~companion.runs.turns.Air`;
- :class:`~companion.runs.guard.Guard` and :class:`~companion.runs.edits.Edits` -- the
  fail-safe and what changes on the vehicle;

and runs their work in one :class:`asyncio.TaskGroup`, following the vehicle through its
autopilot's telemetry (:class:`companion.mission.autopilot.AutopilotBase`: MAVSDK, or a mock
vehicle in the same process).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
import time
from collections.abc import Coroutine
from typing import Any

from companion import logs
from companion.auth.beacon_keys import BeaconKeys
from companion.auth.session import BOOT_SIZE
from companion.context import Context
from companion.events import (
    WARNINGS,
    Event,
    EventKind,
    MissionRead,
    Payload,
    Problem,
    TaskFailed,
)
from companion.mission.autopilot import AutopilotBase
from companion.mission.items import MissionError
from companion.mission.own_flight import TIMING_EVERY_S, OwnFlight
from companion.mission.vehicle import VehicleState
from companion.neighbours.beacon import keys_hash
from companion.neighbours.neighbourhood import Neighbourhood
from companion.neighbours.registry import Neighbours
from companion.neighbours.sender import BeaconSender, Cadence
from companion.radio.endpoint import LinkEndpoint
from companion.runs.alice import AliceRuns
from companion.runs.bob import BobAnswers, Responding
from companion.runs.budget import RunLedger, RunLimits
from companion.runs.edits import Edits
from companion.runs.estimates import RunEstimates
from companion.runs.guard import Guard
from companion.runs.standing import Standing
from companion.runs.turns import Air
from companion.settings import CompanionSettings, Credentials
from companion.state import StateStore
from companion.tasks import TaskScope
from protocol.messages import Suite
from protocol.paper.keys import BobKeys

__all__ = ["Companion", "CompanionSettings", "Credentials"]

log = logging.getLogger("companion")
EDIT_GRACE_S = 20.0  # an upload and its read-backs take seconds over a real link
STOP_GRACE_S = 10.0  # a stop waits this long (real s) for the task group to end
POSITION_RATE_HZ = 5.0  # telemetry position updates asked of the autopilot
AUTOPILOT_SILENT_S = 5.0  # no position from the autopilot this long (real s): a warning


class Companion:
    """One drone's companion: ``await Companion(...).start()``, ``await stop()``."""

    def __init__(
        self,
        settings: CompanionSettings,
        endpoint: LinkEndpoint,
        autopilot: AutopilotBase,
        credentials: Credentials,
    ) -> None:
        identity = credentials.identity
        if identity.cert.node != settings.node:
            raise ValueError(
                f"the certificate is for node {identity.cert.node}, not {settings.node}"
            )
        self.settings = settings
        self.endpoint = endpoint
        self.autopilot = autopilot
        self.clock = endpoint.clock
        self.events: list[Event] = []
        self.epoch = 0.0  # events count link seconds from here (the start, a replay's zero)
        self._tasks = TaskScope(f"node{settings.node}", log, self._task_failed, STOP_GRACE_S)
        ctx = Context(settings, self.clock, self.record, self.spawn)
        self.store = StateStore(credentials.state_dir)
        bob_keys = BobKeys.generate() if settings.suite is Suite.PAPER else None
        boot = secrets.token_bytes(BOOT_SIZE)  # new at every start: peers drop our setups
        self.sender, registry, cadence = self._beacons(credentials, boot, bob_keys)
        self.vehicle = VehicleState()
        self.flight = OwnFlight(ctx, self.vehicle, self.sender.announce)
        self.neighbourhood = Neighbourhood(
            ctx, endpoint, self.flight, registry, self.sender, cadence
        )
        self.edits = Edits(ctx, self.flight, self.neighbourhood, autopilot, self.sender.announce)
        self.air = Air()
        self._runs(ctx, Responding(identity, bob_keys, boot, self.store))
        self.neighbourhood.on_slots = self.edits.slots_heard
        self.neighbourhood.on_news = self.alice.wake

    def _beacons(
        self, credentials: Credentials, boot: bytes, bob_keys: BobKeys | None
    ) -> tuple[BeaconSender, Neighbours, Cadence]:
        """Our beacons out (a beacon key new at every start) and theirs checked."""
        settings = self.settings
        beacon_keys = BeaconKeys()
        public = bob_keys.public_bytes() if bob_keys is not None else b""
        registry = Neighbours(
            credentials.trust,
            self.store,
            credentials.identity.cert,
            beacon_keys,
            settings.max_clock_skew_s,
        )
        cadence = Cadence.of(self.endpoint.profile, settings.beacon_interval_s)
        sender = BeaconSender(
            settings.node,
            self.endpoint,
            credentials.identity,
            beacon_keys,
            keys_hash(boot, beacon_keys.public, public),  # what our signed beacons announce
            self.store,
            registry,
            cadence,
        )
        return sender, registry, cadence

    def _runs(self, ctx: Context, me: Responding) -> None:
        """Runs as Alice, answers as Bob, and the fail-safe, on one budget and one radio."""
        settings = self.settings
        limits = RunLimits(
            settings.max_runs_per_peer,
            settings.max_runs_total,
            settings.run_window_s,
            settings.max_answer_bits_per_peer,
        )
        ledger = RunLedger(self.store, limits)
        estimates = RunEstimates(settings, self.endpoint)
        standing = Standing(self.flight, self.neighbourhood)
        self.guard = Guard(
            ctx, self.endpoint, self.flight, self.neighbourhood, standing, self.edits, estimates
        )
        self.alice = AliceRuns(
            ctx,
            self.endpoint,
            me.identity,
            self.flight,
            self.neighbourhood,
            standing,
            self.edits,
            self.guard,
            estimates,
            self.air,
            ledger,
        )
        self.bob = BobAnswers(
            ctx,
            self.endpoint,
            me,
            self.flight,
            self.neighbourhood,
            self.air,
            ledger,
            on_done=self.alice.wake,
        )

    def record(self, kind: EventKind, payload: Payload) -> None:
        """An event at link seconds since :attr:`epoch` (the start, or the replay's zero),
        logged as ``key=value`` text and as a JSON line (:mod:`companion.logs`)."""
        event = Event(self.clock.now() - self.epoch, kind, payload)
        self.events.append(event)
        level = logging.WARNING if kind in WARNINGS else logging.INFO
        text = f"node {self.settings.node}: {kind.replace('_', ' ')}"
        logs.event(log, level, kind, text, t_s=round(event.t, 1), **event.detail)

    def spawn(self, work: Coroutine[Any, Any, None], name: str = "child") -> asyncio.Task[None]:
        """A task in the companion's task group (opened by :meth:`start` or
        :meth:`start_radio`; cancelled by :meth:`stop`).  Its failure is logged with its
        traceback and recorded (``task_failed``) -- a companion whose beacons or answers
        died must say so, not go quiet -- and ends neither the group nor its other tasks."""
        return self._tasks.spawn(work, name)

    def _task_failed(self, name: str, exc: BaseException) -> None:
        self.record(EventKind.TASK_FAILED, TaskFailed(task=name, error=repr(exc)))

    async def start(self) -> None:
        """Read the mission, start the radio, and run every part until :meth:`stop`."""
        self.epoch = self.clock.now()
        items = await self.autopilot.download()
        home = None if self.settings.ardupilot else await self.autopilot.home()
        try:  # (ArduPilot's home is item 0 of the mission)
            self.flight.load(items, home)
        except MissionError as exc:  # e.g. a DO_JUMP to nowhere: fly, but compare nothing
            self.flight.load(items, home, self.flight.path)
            self.record(EventKind.MISSION_INVALID, Problem(error=str(exc)))
        self.record(
            EventKind.MISSION,
            MissionRead(
                items=len(items),
                segments=self.flight.path.segments,
                home=home is not None or self.settings.ardupilot,
            ),
        )
        await self.endpoint.start()
        await self._open(
            ("telemetry", self._telemetry()),
            ("progress", self._progress()),
            ("armed", self._armed()),
            ("flight mode", self._flight_mode()),
            ("autopilot watch", self._autopilot_watch()),
            ("guard", self.guard.guard()),
            ("timing", self._timing_watch()),
            *self._radio_parts(),
        )

    async def start_radio(self) -> None:
        """Only the parts on the radio (the endpoint started, the mission loaded): for a
        simulation whose vehicle is driven by hand."""
        await self._open(*self._radio_parts())

    def _radio_parts(self) -> list[tuple[str, Coroutine[Any, Any, None]]]:
        """Our beacons out (certificates, positions), theirs in, answers as Bob, our runs as
        Alice."""
        return [
            ("certificates", self.sender.certificates()),
            ("beacons", self.sender.positions(self.neighbourhood.own_beacon, self._on_air)),
            ("listen", self.neighbourhood.listen()),
            ("serve", self.bob.serve()),
            ("alice", self.alice.loop()),
        ]

    async def _open(self, *parts: tuple[str, Coroutine[Any, Any, None]]) -> None:
        """The task group, with ``parts`` in it."""
        await self._tasks.open()
        for name, work in parts:
            self.spawn(work, name)

    @property
    def running(self) -> bool:
        """Started and not stopped: the task group is up."""
        return self._tasks.running

    def _on_air(self) -> bool:
        """A run is on the air (ours or an answer): a beacon would only collide with it."""
        return self.air.in_run or self.endpoint.busy()

    async def stop(self) -> None:
        """Cancel every task and close the radio and the store.  A mission edit under way is
        let finish first (bounded): cut between upload and read-back it would leave the
        vehicle holding a mission the companion never recorded."""
        editing = False
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self.flight.editing.acquire(), EDIT_GRACE_S)
            editing = True
        await self._tasks.close()  # (bounded: a stop never hangs on one task)
        if editing:
            self.flight.editing.release()
        await self.endpoint.close()
        self.store.close()

    async def _telemetry(self) -> None:
        async for p in self.autopilot.positions(POSITION_RATE_HZ):
            now = self.clock.now()
            if self.vehicle.moved(p.lat_deg, p.lon_deg, p.amsl_m, p.relative_m, now):
                self.sender.announce()  # taking off: announce it
            self.flight.note_position()

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
        """Every few seconds: is the vehicle still within its windows?
        (:meth:`OwnFlight.keep_time`)"""
        while True:
            await self.clock.sleep(TIMING_EVERY_S)
            self.flight.keep_time()

    async def _progress(self) -> None:
        async for current, total in self.autopilot.progress():
            self.flight.progress(current, total, self.clock.now())
