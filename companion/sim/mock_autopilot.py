"""A mock autopilot that speaks real MAVLink 2 over UDP (pymavlink for encoding only).

Enough of PX4 (or ArduPilot) for MAVSDK and any ground station: HEARTBEAT from component 1,
AUTOPILOT_VERSION and HOME_POSITION, the mission protocol for the mission, fence and rally
types (:mod:`companion.mock_missions`), command acknowledgements, GLOBAL_POSITION_INT
telemetry, and a kinematic flight model that flies the stored mission in scaled time,
DO_JUMP loops included.  Links as PX4 SITL (:mod:`companion.mock_links`): instance i has an
API link (binds 14580+i, sends to 14540+i) and a GCS link (binds 18570+i, sends to 14550),
system id i+1.  The firmware's personality (:mod:`companion.autopilots`) decides which items
are refused, how they are stored, and where an upload leaves the current item (PX4: at the
item marked current in the upload, in flight too; ArduPilot: where it was).  Faults can be
injected (dropped replies, latency, ignored messages, rejected uploads, vanishing).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from protocol.geodesy import ground_offset, moved

from ..autopilots import personality
from ..flightpath import DO_JUMP
from ..mission import (
    FRAMES_AMSL,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    MissionItem,
)
from . import mock_links as wire
from .mock_links import PX4_BIND, PX4_GCS_BIND, PX4_GCS_SEND, PX4_SEND, Faults, Link
from .mock_missions import MissionServer, item_message

__all__ = ["PX4_BIND", "PX4_SEND", "Faults", "FlightModel", "MockAutopilot", "item_message"]


@dataclass(frozen=True)
class FlightModel:
    """Kinematics of the simulated multicopter and how fast simulated time runs."""

    cruise_m_s: float = 10.0
    climb_m_s: float = 3.0
    acceptance_m: float = 2.0
    time_scale: float = 1.0  # simulated seconds per real second
    rate_hz: float = 10.0


class MockAutopilot(MissionServer):
    """``await MockAutopilot(instance, mission=...).start()``; ``await stop()``.

    Ports: ``bind_port``/``send_port`` are the API link (default 14580+i / 14540+i).  The GCS
    link binds ``gcs_bind_port`` and sends to ``gcs_send_port`` (default 14550); by default
    it is opened (18570+i) only when ``bind_port`` is not given -- explicit ports are for tests
    and replays that run many mocks in one process --, and ``gcs_bind_port=0`` never opens it.
    """

    def __init__(
        self,
        instance: int = 0,
        *,
        mission: list[MissionItem] | None = None,
        home: tuple[float, float, float] = (47.397742, 8.545594, 488.0),
        ardupilot: bool = False,
        faults: Faults | None = None,
        flight: FlightModel | None = None,
        host: str = "127.0.0.1",
        bind_port: int | None = None,
        send_port: int | None = None,
        gcs_bind_port: int | None = None,
        gcs_send_port: int = PX4_GCS_SEND,
    ) -> None:
        self.instance = instance
        self.sysid = instance + 1
        self.ardupilot = ardupilot
        self.flight = flight or FlightModel()
        self.host = host
        self.bind_port = PX4_BIND + instance if bind_port is None else bind_port
        self.send_port = PX4_SEND + instance if send_port is None else send_port
        if gcs_bind_port is None:
            gcs_bind_port = PX4_GCS_BIND + instance if bind_port is None else 0
        self.gcs_bind_port, self.gcs_send_port = gcs_bind_port, gcs_send_port
        self.mav = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=1)  # encoder
        super().__init__(personality(ardupilot), home, faults or Faults(), mission)
        self.current = 1 if ardupilot and len(self.mission) > 1 else 0
        self.lat, self.lon, self.alt = home[0], home[1], 0.0  # alt: metres above home
        self.armed = False
        self.flying = False
        self.mission_running = False
        self.holding = False  # paused in flight (hold / loiter mode)
        self.trajectory: list[tuple[float, float, float, float]] = []
        self.reached: list[int] = []  # items reached in flight, in order (MISSION_ITEM_REACHED)
        self.received: dict[str, int] = {}
        self.links: list[Link] = []
        self.api_link: Link | None = None
        self.gcs_link: Link | None = None
        self._replies = 0
        self._tasks: list[asyncio.Task[None]] = []
        self._started = 0.0
        self.origin = 0.0
        self._sim_time = 0.0
        self._takeoff_alt: float | None = None
        self._rtl_descending = False
        self._hold_until: float | None = None

    # ------------------------------------------------------------------ lifecycle

    async def start(self, origin: float | None = None) -> MockAutopilot:
        """Open the links and run; ``origin`` (time.monotonic) is simulated time zero."""
        self.api_link = Link("api", self.host, self.bind_port, self.send_port, self.sysid, self._on)
        self.links = [self.api_link]
        if self.gcs_bind_port:
            self.gcs_link = Link(
                "gcs", self.host, self.gcs_bind_port, self.gcs_send_port, self.sysid, self._on
            )
            self.links.append(self.gcs_link)
        try:
            for link in self.links:
                await link.open()
        except BaseException:
            for link in self.links:
                link.close()
            raise
        self._started = time.monotonic()
        self.origin = self._started if origin is None else origin
        self._tasks = [
            asyncio.create_task(self._heartbeats()),
            asyncio.create_task(self._fly()),
        ]
        return self

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        for link in self.links:
            link.close()

    async def __aenter__(self) -> MockAutopilot:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def _vanished(self) -> bool:
        limit = self.faults.vanish_after_s
        return limit is not None and time.monotonic() - self._started > limit

    # ------------------------------------------------------------------ sending

    def _send(self, message: Any, link: Link | None = None, *, reply: bool = False) -> None:
        """To ``link`` (a reply: faults apply) or, without one, on every link."""
        if self._vanished():
            return
        if reply:
            self._replies += 1
            if self.faults.drop_every and self._replies % self.faults.drop_every == 0:
                return
        delay = self.faults.latency_s if reply else 0.0
        for each in [link] if link is not None else self.links:
            each.send(message, delay)

    def _reply(self, link: Link, message: Any) -> None:
        self._send(message, link, reply=True)

    def _heartbeat(self) -> None:
        self._send(wire.heartbeat(self.mav, self.ardupilot, self.armed, self.mission_running))

    def _report_current(self) -> None:
        self._send(self.mav.mission_current_encode(self.current, len(self.mission), 0, 0))

    async def _heartbeats(self) -> None:
        while True:
            self._heartbeat()
            self._report_current()
            self._send(wire.home_position(self.mav, self.home))
            await asyncio.sleep(1.0)

    # ------------------------------------------------------------------ receiving

    def _on(self, link: Link, message: Any) -> None:
        """A message arrived on ``link``: dispatch to ``_on_<name>(link, message)``."""
        if self._vanished():
            return
        name = message.get_type()
        if name in self.faults.ignore:
            return
        target = getattr(message, "target_system", self.sysid)
        if target not in (0, self.sysid):
            return
        self.received[name] = self.received.get(name, 0) + 1
        handler = getattr(self, f"_on_{name.lower()}", None)
        if handler is not None:
            handler(link, message)

    def _mission_replaced(self, marked: int | None) -> None:
        """PX4 restarts at the item marked current (in flight too), else keeps its index;
        ArduPilot ignores the mark: keeps its index in flight, item 1 on the ground."""
        last = max(len(self.mission) - 1, 0)
        before = self.current
        if self.personality.home_is_item0:
            self.current = min(self.current, last) if self.flying else min(1, last)
        elif marked is not None:
            self.current = min(marked, last)
            self._hold_until, self._rtl_descending = None, False  # the item starts again
        else:
            self.current = min(self.current, last)
        if self.current != before:
            self._hold_until, self._rtl_descending = None, False
        if len(self.mission) <= int(self.personality.home_is_item0):  # nothing left to fly
            self.mission_running = False
        self._jumps.clear()

    def _mission_cleared(self) -> None:
        self.current = 0
        self.mission_running = False
        self._jumps.clear()

    def _set_current(self, seq: int) -> bool:
        if not 0 <= seq < len(self.mission):
            return False
        if seq != self.current:
            self._hold_until, self._rtl_descending = None, False
        self.current = seq
        return True

    def _on_mission_set_current(self, link: Link, m: Any) -> None:
        self._set_current(m.seq)
        self._reply(link, self.mav.mission_current_encode(self.current, len(self.mission), 0, 0))

    def _startable(self) -> bool:
        """Would the firmware fly this mission?  (PX4 denies a take-off at 0,0: "first
        waypoint too far from home".)"""
        p = self.personality
        return bool(self.mission) and not (
            p.problems(self.mission) or p.start_problems(self.mission)
        )

    # commands
    def _on_command_long(self, link: Link, m: Any) -> None:
        result = mavlink.MAV_RESULT_ACCEPTED
        command = m.command
        report_current = False
        if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            if int(m.param1) == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
                self._reply(link, wire.autopilot_version(self.mav, self.sysid))
            elif int(m.param1) == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
                self._reply(link, wire.home_position(self.mav, self.home))
            else:
                result = mavlink.MAV_RESULT_UNSUPPORTED
        elif command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._reply(link, wire.autopilot_version(self.mav, self.sysid))
        elif command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            self.armed = m.param1 == 1
        elif command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if not self.armed:
                result = mavlink.MAV_RESULT_DENIED
            else:
                self._takeoff_alt = 2.5 if math.isnan(m.param7) else float(m.param7) - self.home[2]
                self.flying = True
        elif command == mavlink.MAV_CMD_MISSION_START:
            if not self.armed or not self._startable():
                result = mavlink.MAV_RESULT_DENIED
            else:
                self._start_mission()
        elif command == mavlink.MAV_CMD_DO_SET_MODE:
            result = self._set_mode(m)
        elif command == mavlink.MAV_CMD_DO_SET_MISSION_CURRENT and not self.ardupilot:
            result = mavlink.MAV_RESULT_UNSUPPORTED  # PX4 v1.16 (measured): the message only
        elif command == mavlink.MAV_CMD_DO_SET_MISSION_CURRENT:
            seq = m.param1
            keep = seq == -1  # -1: the current item (a reset, index kept)
            ok = keep or (math.isfinite(seq) and seq == int(seq) and self._set_current(int(seq)))
            result = mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_DENIED
            report_current = ok
        elif command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            if int(m.param1) == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
                self._reply(link, wire.home_position(self.mav, self.home))
        else:
            result = mavlink.MAV_RESULT_UNSUPPORTED
        ack = self.mav.command_ack_encode(
            command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent()
        )
        self._reply(link, ack)
        if report_current:
            self._report_current()

    def _set_mode(self, m: Any) -> int:
        """Hold (PX4 AUTO.LOITER, ArduPilot LOITER/BRAKE) pauses the mission where the vehicle
        is; mission mode (PX4 AUTO.MISSION, ArduPilot AUTO) resumes it, or is denied when the
        firmware would not fly the mission.  Other modes: accepted."""
        if self.ardupilot:
            hold, resume = int(m.param2) in (5, 17), int(m.param2) == 3
        else:
            main, sub = int(m.param2), int(m.param3)
            hold, resume = (main, sub) == (4, 3), (main, sub) == (4, 4)
        if hold and self.flying:
            self.mission_running = False
            self.holding = True
        elif resume and self.armed and self.mission:
            if not self._startable():
                return int(mavlink.MAV_RESULT_DENIED)
            self._start_mission()
            self.holding = False
        return int(mavlink.MAV_RESULT_ACCEPTED)

    # ------------------------------------------------------------------ flight

    def _target(self, item: MissionItem) -> tuple[float, float, float] | None:
        """(lat, lon, metres above home) the vehicle flies to for this item, if any."""
        if item.command == NAV_RETURN_TO_LAUNCH:  # home at the current height, then down
            return self.home[0], self.home[1], 0.0 if self._rtl_descending else self.alt
        if item.command == NAV_TAKEOFF and not item.has_position:
            return self.lat, self.lon, item.z - (self.home[2] if item.frame in FRAMES_AMSL else 0)
        if not item.has_position:
            return None
        alt = item.z - self.home[2] if item.frame in FRAMES_AMSL else item.z
        if item.command == NAV_LAND:
            alt = 0.0
        return item.x / 1e7, item.y / 1e7, alt

    def _go_to(self, index: int | None) -> None:
        if index is None:
            self.mission_running = False  # end of the mission: hold position (PX4: loiter)
        else:
            self.current = index
        self._report_current()

    def _step(self, dt: float) -> None:
        f = self.flight
        target = None
        if self.mission_running and self.current < len(self.mission):
            if self.ardupilot and self.current == 0:  # home is not flown to
                self.current = 1
                return
            if self.mission[self.current].command == DO_JUMP:
                self._go_to(self._resolve(self.current))
                return
            target = self._target(self.mission[self.current])
            if target is None:  # an item without a position: done at once
                self._advance()
                return
        elif self._takeoff_alt is not None:
            target = (self.lat, self.lon, self._takeoff_alt)
        if target is None or not self.flying:
            return
        north, east = ground_offset(self.lat, self.lon, target[0], target[1])
        dist = math.hypot(north, east)
        step = min(dist, f.cruise_m_s * dt)
        if dist > 0:
            self.lat, self.lon = moved(self.lat, self.lon, north * step / dist, east * step / dist)
        dz = target[2] - self.alt
        self.alt += max(-f.climb_m_s * dt, min(f.climb_m_s * dt, dz))
        if dist - step <= f.acceptance_m and abs(target[2] - self.alt) <= 0.5:
            if self.mission_running:
                self._advance()
            else:
                self._takeoff_alt = None

    def _advance(self) -> None:
        """The current item is reached (or has no position): report it and go on."""
        item = self.mission[self.current]
        if item.command == NAV_LOITER_TIME and item.has_position:
            if self._hold_until is None:
                self._hold_until = self._sim_time + max(item.param1, 0.0)
            if self._sim_time < self._hold_until:
                return  # holding over the loiter point
            self._hold_until = None
        if item.command == NAV_RETURN_TO_LAUNCH and not self._rtl_descending:
            self._rtl_descending = True  # over home: now land there
            return
        self.reached.append(self.current)
        self._send(self.mav.mission_item_reached_encode(self.current))
        if item.command in (NAV_LAND, NAV_RETURN_TO_LAUNCH):
            self.alt, self.armed = 0.0, False
            self.mission_running = self.flying = self._rtl_descending = False
            self._report_current()
        else:
            self._go_to(self._resolve(self.current + 1))

    def take_off(self) -> None:
        """Armed, flying the mission from the current item (what arm + MISSION_START do)."""
        self._start_mission()

    def _start_mission(self) -> None:
        if not self.flying:  # a new flight: the mission starts again, jump counters too
            self._jumps.clear()
        self.armed = self.flying = self.mission_running = True

    def restart_clock(self, origin: float) -> None:
        """Make ``origin`` (time.monotonic) simulated time zero and forget the track so far."""
        self.origin, self._sim_time = origin, 0.0
        self.trajectory.clear()

    def advance(self, dt: float) -> None:
        """One step of the flight model, recorded in the trajectory."""
        self._sim_time += dt
        self._step(dt)
        self.trajectory.append((self._sim_time, self.lat, self.lon, self.home[2] + self.alt))

    def sim_time(self) -> float:
        """Simulated seconds since ``origin`` (shared by the vehicles of a replay)."""
        return (time.monotonic() - self.origin) * self.flight.time_scale

    async def _fly(self) -> None:
        """Advance the model to the simulated time in steps of at most 0.5 s, whatever the
        time scale, recording every step; send telemetry once per wake-up."""
        period = 1.0 / self.flight.rate_hz
        while True:
            await asyncio.sleep(period)
            if self._vanished():
                continue
            target = self.sim_time()
            steps = max(1, math.ceil((target - self._sim_time) / 0.5))
            dt = (target - self._sim_time) / steps
            for _ in range(steps):
                self.advance(dt)
            self._send(
                self.mav.global_position_int_encode(
                    int(self._sim_time * 1000) & 0xFFFFFFFF,
                    round(self.lat * 1e7),
                    round(self.lon * 1e7),
                    round((self.home[2] + self.alt) * 1000),
                    round(self.alt * 1000),
                    0,
                    0,
                    0,
                    0,
                )
            )
