"""A mock autopilot that speaks real MAVLink 2 over UDP (pymavlink for encoding only).

Enough of PX4 (or ArduPilot) for MAVSDK and any ground station: HEARTBEAT from component 1,
AUTOPILOT_VERSION and HOME_POSITION, the mission protocol for the mission, fence and rally
types (:mod:`companion.sim.mock_missions`, the store), command acknowledgements and
GLOBAL_POSITION_INT telemetry of the kinematic flight (:mod:`companion.sim.mock_flight`),
which flies the stored mission in simulated time, DO_JUMP loops included.  This module is
the MAVLink endpoint.  Links as PX4 SITL (:mod:`companion.sim.mock_links`): instance i has an
API link (binds 14580+i, sends to 14540+i) and a GCS link (binds 18570+i, sends to 14550),
system id i+1.  The firmware's personality (:mod:`companion.mission.personalities`) decides which
items are refused, how they are stored, and where an upload leaves the current item (PX4: at the
item marked current in the upload, in flight too; ArduPilot: where it was).  Faults can be
injected (dropped replies, latency, ignored messages, rejected uploads, vanishing).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from companion.mission.items import MissionItem
from companion.radio.clock import Clock
from companion.sim import mock_links as wire
from companion.sim.mock_flight import FlightModel, MockFlight
from companion.sim.mock_links import PX4_BIND, PX4_GCS_BIND, PX4_GCS_SEND, PX4_SEND, Faults, Link
from companion.sim.mock_missions import item_message
from companion.tasks import spawn

__all__ = ["PX4_BIND", "PX4_SEND", "Faults", "FlightModel", "MockAutopilot", "item_message"]
log = logging.getLogger(__name__)


class MockAutopilot(MockFlight):
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
        clock: Clock | None = None,
    ) -> None:
        self.instance = instance
        self.sysid = instance + 1
        self.host = host
        self.bind_port = PX4_BIND + instance if bind_port is None else bind_port
        self.send_port = PX4_SEND + instance if send_port is None else send_port
        if gcs_bind_port is None:
            gcs_bind_port = PX4_GCS_BIND + instance if bind_port is None else 0
        self.gcs_bind_port, self.gcs_send_port = gcs_bind_port, gcs_send_port
        self.mav = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=1)  # encoder
        super().__init__(
            mission=mission,
            home=home,
            ardupilot=ardupilot,
            faults=faults,
            flight=flight,
            clock=clock,
        )
        self.received: dict[str, int] = {}
        self.links: list[Link] = []
        self.api_link: Link | None = None
        self.gcs_link: Link | None = None
        self._replies = 0
        self._tasks: list[asyncio.Task[None]] = []
        self._started = 0.0

    def _item_reached(self, seq: int) -> None:
        self._send(self.mav.mission_item_reached_encode(seq))

    # ------------------------------------------------------------------ lifecycle

    async def start(self, origin: float | None = None, *, links: bool = True) -> MockAutopilot:
        """Open the links and run; ``origin`` (a time of :attr:`now`) is simulated time zero.
        Without ``links`` it only flies: no MAVLink, for a caller in this process
        (:mod:`companion.sim.inproc`)."""
        if links:
            await self._open_links()
        self._started = time.monotonic()
        self.origin = self.now() if origin is None else origin
        self._tasks = [spawn(self._fly(), name=f"mock-{self.sysid}-flight", log=log)]
        if links:  # a failure is logged when it happens (the mock would go quiet)
            self._tasks.append(
                spawn(self._heartbeats(), name=f"mock-{self.sysid}-heartbeats", log=log)
            )
        return self

    async def _open_links(self) -> None:
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
        in_air = self.flying and not self.mission_running  # paused, or the mission is over
        self._send(
            wire.heartbeat(self.mav, self.ardupilot, self.armed, self.mission_running, in_air)
        )

    def _report_current(self) -> None:
        self._send(self.mav.mission_current_encode(self.current, len(self.mission), 0, 0))

    async def _heartbeats(self) -> None:
        """HEARTBEAT, MISSION_CURRENT and HOME_POSITION once a simulated second, as PX4 SITL
        sends them in its lock-step time (at most 50 a real second)."""
        period = 1.0 / min(max(self.flight.time_scale, 1.0), 50.0)
        while True:
            self._heartbeat()
            self._report_current()
            self._send(wire.home_position(self.mav, self.home))
            await asyncio.sleep(period)

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

    def _on_mission_set_current(self, link: Link, m: Any) -> None:
        self._set_current(m.seq)
        self._reply(link, self.mav.mission_current_encode(self.current, len(self.mission), 0, 0))

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
                self._guided_takeoff(
                    2.5 if math.isnan(m.param7) else float(m.param7) - self.home[2]
                )
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
            self._hold()
        elif resume and self.armed and self.mission:
            if not self._startable():
                return int(mavlink.MAV_RESULT_DENIED)
            self._start_mission()
        return int(mavlink.MAV_RESULT_ACCEPTED)

    async def _fly(self) -> None:
        """Advance the model to the simulated time in steps of at most 0.5 s, whatever the
        time scale, recording every step; send telemetry once per wake-up."""
        period = 1.0 / self.flight.rate_hz
        while True:
            # parked and disarmed (waiting for its take-off) nothing moves: a look a second
            await asyncio.sleep(period if self.armed or self.flying else max(period, 1.0))
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
