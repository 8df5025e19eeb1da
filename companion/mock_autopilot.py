"""A mock autopilot that speaks real MAVLink 2 over UDP (pymavlink for encoding only).

Enough of PX4 (or ArduPilot) for MAVSDK and any ground station: HEARTBEAT from component 1,
AUTOPILOT_VERSION and HOME_POSITION on request, the whole mission protocol for the mission,
fence and rally types (download, upload, clear, set current, MISSION_CURRENT), command
acknowledgements, GLOBAL_POSITION_INT telemetry, and a kinematic flight model that flies the
stored mission in scaled time.  Ports as PX4 SITL: instance i binds 14580+i, sends to 14540+i,
system id i+1.  Uploads are atomic: the stored mission changes only when the last item arrived;
an upload during flight takes effect as on PX4, continuing at the current item.  Faults can be
injected (dropped replies, latency, ignored messages, rejected uploads, vanishing).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from dataclasses import dataclass, field
from typing import Any, cast

from pymavlink.dialects.v20 import common as mavlink

from .mission import (
    EARTH_RADIUS_M,
    FRAMES_AMSL,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    MissionItem,
    ground_offset,
)

PX4_BIND, PX4_SEND = 14580, 14540
ACCEPTED = mavlink.MAV_MISSION_ACCEPTED
RETRY_S, RETRIES = 0.25, 8  # the autopilot drives uploads: it re-requests lost items


@dataclass(frozen=True)
class Faults:
    """Fault injection: every field off by default."""

    drop_every: int = 0  # drop every k-th mission-protocol reply
    latency_s: float = 0.0  # added to every reply
    ignore: frozenset[str] = frozenset()  # MAVLink message names to ignore, e.g. MISSION_COUNT
    reject_upload: int | None = None  # MAV_MISSION_RESULT to answer every upload with
    vanish_after_s: float | None = None  # stop answering and sending after this (real) time
    garble_uploads: int = 0  # store the next N uploads with the last item's altitude wrong


@dataclass(frozen=True)
class FlightModel:
    cruise_m_s: float = 10.0
    climb_m_s: float = 3.0
    acceptance_m: float = 2.0
    time_scale: float = 1.0  # simulated seconds per real second
    rate_hz: float = 10.0


@dataclass
class _Upload:
    mission_type: int
    count: int
    items: list[MissionItem] = field(default_factory=list)
    tries: int = 0
    timer: asyncio.TimerHandle | None = None


def _moved(lat: float, lon: float, north: float, east: float) -> tuple[float, float]:
    """The inverse of :func:`ground_offset`: a point moved by (north, east) metres."""
    dlat = math.degrees(north / EARTH_RADIUS_M)
    dlon = math.degrees(east / (EARTH_RADIUS_M * math.cos(math.radians(lat))))
    return lat + dlat, lon + dlon


def item_message(mav: Any, target_system: int, target_component: int, it: MissionItem) -> Any:
    """MISSION_ITEM_INT for one item."""
    return mav.mission_item_int_encode(
        target_system,
        target_component,
        it.seq,
        it.frame,
        it.command,
        it.current,
        it.autocontinue,
        it.param1,
        it.param2,
        it.param3,
        it.param4,
        it.x,
        it.y,
        it.z,
        it.mission_type,
    )


class MockAutopilot(asyncio.DatagramProtocol):
    """``await MockAutopilot(instance, mission=...).start()``; ``await stop()``."""

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
    ) -> None:
        self.instance = instance
        self.sysid = instance + 1
        self.ardupilot = ardupilot
        self.faults = faults or Faults()
        self.flight = flight or FlightModel()
        self.host = host
        self.bind_port = PX4_BIND + instance if bind_port is None else bind_port
        self.send_port = PX4_SEND + instance if send_port is None else send_port
        self.home = home
        self.mav = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=1)
        self.mav.robust_parsing = True
        self.stores: dict[int, list[MissionItem]] = {0: [], 1: [], 2: []}
        if mission:
            self.stores[0] = [m.replace(seq=i, current=0) for i, m in enumerate(mission)]
        if ardupilot and not self.stores[0]:
            self.stores[0] = [self._home_item()]
        self.current = 1 if ardupilot and len(self.stores[0]) > 1 else 0
        self.lat, self.lon, self.alt = home[0], home[1], 0.0  # alt: metres above home
        self.armed = False
        self.flying = False
        self.mission_running = False
        self.holding = False  # paused in flight (hold / loiter mode)
        self.trajectory: list[tuple[float, float, float, float]] = []
        self.uploads_accepted = 0
        self.received: dict[str, int] = {}
        self._upload: _Upload | None = None
        self._replies = 0
        self._peer: tuple[str, int] = (host, self.send_port)
        self._transport: asyncio.DatagramTransport | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._started = 0.0
        self.origin = 0.0
        self._sim_time = 0.0
        self._takeoff_alt: float | None = None
        self._garbles_left = self.faults.garble_uploads
        self._rtl_descending = False
        self._hold_until: float | None = None

    # ------------------------------------------------------------------ lifecycle

    async def start(self, origin: float | None = None) -> MockAutopilot:
        """Bind and run; ``origin`` (time.monotonic) is simulated time zero."""
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(lambda: self, local_addr=(self.host, self.bind_port))
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
        if self._transport is not None:
            self._transport.close()

    async def __aenter__(self) -> MockAutopilot:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    @property
    def mission(self) -> list[MissionItem]:
        return self.stores[0]

    def _vanished(self) -> bool:
        limit = self.faults.vanish_after_s
        return limit is not None and time.monotonic() - self._started > limit

    def _home_item(self) -> MissionItem:
        lat, lon, alt = self.home
        return MissionItem(0, 0, 16, 0, 1, 0, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), alt)

    # ------------------------------------------------------------------ sending

    def _send(self, message: Any, *, reply: bool = False) -> None:
        if self._transport is None or self._transport.is_closing() or self._vanished():
            return
        if reply:
            self._replies += 1
            if self.faults.drop_every and self._replies % self.faults.drop_every == 0:
                return
        data = message.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        if reply and self.faults.latency_s:
            asyncio.get_running_loop().call_later(
                self.faults.latency_s, self._transport.sendto, data, self._peer
            )
        else:
            self._transport.sendto(data, self._peer)

    def _heartbeat(self) -> None:
        autopilot = (
            mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA if self.ardupilot else mavlink.MAV_AUTOPILOT_PX4
        )
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        custom = (4 << 16) | (4 << 24) if self.mission_running and not self.ardupilot else 0
        state = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        self._send(
            self.mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, autopilot, base, custom, state, 3)
        )

    async def _heartbeats(self) -> None:
        while True:
            self._heartbeat()
            self._send(self.mav.mission_current_encode(self.current, len(self.mission), 0, 0))
            await asyncio.sleep(1.0)

    # ------------------------------------------------------------------ receiving

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if self._vanished():
            return
        try:
            messages = self.mav.parse_buffer(data) or []
        except mavlink.MAVError:
            return
        for message in messages:
            name = message.get_type()
            if name == "BAD_DATA" or name in self.faults.ignore:
                continue
            target = getattr(message, "target_system", self.sysid)
            if target not in (0, self.sysid):
                continue
            self._peer = addr
            self.received[name] = self.received.get(name, 0) + 1
            handler = getattr(self, f"_on_{name.lower()}", None)
            if handler is not None:
                handler(message)

    # mission download
    def _on_mission_request_list(self, m: Any) -> None:
        store = self.stores.get(m.mission_type, [])
        self._send(
            self.mav.mission_count_encode(
                m.get_srcSystem(), m.get_srcComponent(), len(store), m.mission_type
            ),
            reply=True,
        )

    def _on_mission_request_int(self, m: Any) -> None:
        store = self.stores.get(m.mission_type, [])
        if not 0 <= m.seq < len(store):
            self._ack(m, mavlink.MAV_MISSION_INVALID_SEQUENCE, m.mission_type)
            return
        it = store[m.seq].replace(current=int(m.mission_type == 0 and m.seq == self.current))
        self._send(
            item_message(self.mav, m.get_srcSystem(), m.get_srcComponent(), it),
            reply=True,
        )

    _on_mission_request = _on_mission_request_int

    def _ack(self, m: Any, result: int, mission_type: int) -> None:
        self._send(
            self.mav.mission_ack_encode(
                m.get_srcSystem(), m.get_srcComponent(), result, mission_type
            ),
            reply=True,
        )

    # mission upload (the autopilot drives it)
    def _on_mission_count(self, m: Any) -> None:
        if self._upload and self._upload.timer:
            self._upload.timer.cancel()
        self._upload = None
        if self.faults.reject_upload is not None:
            self._ack(m, self.faults.reject_upload, m.mission_type)
            return
        if m.mission_type not in self.stores:
            self._ack(m, mavlink.MAV_MISSION_UNSUPPORTED, m.mission_type)
            return
        if m.count == 0:
            self._commit(m, [])
            return
        self._upload = _Upload(m.mission_type, m.count)
        self._request(m)

    def _request(self, m: Any) -> None:
        up = self._upload
        if up is None:
            return
        src, comp = m.get_srcSystem(), m.get_srcComponent()
        self._send(
            self.mav.mission_request_int_encode(src, comp, len(up.items), up.mission_type),
            reply=True,
        )
        if up.timer:
            up.timer.cancel()
        up.timer = asyncio.get_running_loop().call_later(RETRY_S, self._retry, m)

    def _retry(self, m: Any) -> None:
        up = self._upload
        if up is None:
            return
        up.tries += 1
        if up.tries > RETRIES:
            self._upload = None
            self._ack(m, mavlink.MAV_MISSION_OPERATION_CANCELLED, up.mission_type)
            return
        self._request(m)

    def _on_mission_item_int(self, m: Any) -> None:
        up = self._upload
        if up is None or m.mission_type != up.mission_type:
            return
        if m.seq == len(up.items):
            up.items.append(
                MissionItem(
                    m.seq,
                    m.frame,
                    m.command,
                    m.current,
                    m.autocontinue,
                    m.param1,
                    m.param2,
                    m.param3,
                    m.param4,
                    m.x,
                    m.y,
                    m.z,
                    m.mission_type,
                )
            )
            up.tries = 0
        if len(up.items) < up.count:
            self._request(m)
            return
        if up.timer:
            up.timer.cancel()
        self._upload = None
        self._commit(m, up.items)

    def _commit(self, m: Any, items: list[MissionItem]) -> None:
        """Replace the store at once (never a mix); in flight, continue at the current item."""
        kind = m.mission_type
        if self._garbles_left and items:  # a partial/garbled write, caught by read-back
            self._garbles_left -= 1
            items = [*items[:-1], items[-1].replace(z=items[-1].z + 1000.0)]
        self.stores[kind] = [it.replace(seq=i, current=0) for i, it in enumerate(items)]
        if kind == 0:
            marked = [it.seq for it in items if it.current]
            if not self.mission_running:
                self.current = marked[0] if marked else (1 if self.ardupilot else 0)
            self.current = min(self.current, max(len(items) - 1, 0))
            self.uploads_accepted += 1
        self._ack(m, ACCEPTED, kind)
        if kind == 0:
            self._send(self.mav.mission_current_encode(self.current, len(items), 0, 0))

    def _on_mission_clear_all(self, m: Any) -> None:
        self.stores[m.mission_type] = (
            [self._home_item()] if (self.ardupilot and m.mission_type == 0) else []
        )
        if m.mission_type == 0:
            self.current = 0
        self._ack(m, ACCEPTED, m.mission_type)

    def _on_mission_set_current(self, m: Any) -> None:
        if 0 <= m.seq < len(self.mission):
            self.current = m.seq
        self._send(
            self.mav.mission_current_encode(self.current, len(self.mission), 0, 0), reply=True
        )

    # commands
    def _on_command_long(self, m: Any) -> None:
        result = mavlink.MAV_RESULT_ACCEPTED
        command = m.command
        if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            if int(m.param1) == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
                self._autopilot_version()
            elif int(m.param1) == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
                self._home_position()
            else:
                result = mavlink.MAV_RESULT_UNSUPPORTED
        elif command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._autopilot_version()
        elif command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            self.armed = m.param1 == 1
        elif command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if not self.armed:
                result = mavlink.MAV_RESULT_DENIED
            else:
                self._takeoff_alt = 2.5 if math.isnan(m.param7) else float(m.param7) - self.home[2]
                self.flying = True
        elif command == mavlink.MAV_CMD_MISSION_START:
            if not self.armed or not self.mission:
                result = mavlink.MAV_RESULT_DENIED
            else:
                self.mission_running = self.flying = True
        elif command == mavlink.MAV_CMD_DO_SET_MODE:
            result = self._set_mode(m)
        elif command != mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = mavlink.MAV_RESULT_UNSUPPORTED
        self._send(
            self.mav.command_ack_encode(
                command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent()
            ),
            reply=True,
        )

    def _set_mode(self, m: Any) -> int:
        """Hold (PX4 AUTO.LOITER, ArduPilot LOITER/BRAKE) pauses the mission where the vehicle
        is; mission mode (PX4 AUTO.MISSION, ArduPilot AUTO) resumes it.  Others: accepted."""
        if self.ardupilot:
            hold, resume = int(m.param2) in (5, 17), int(m.param2) == 3
        else:
            main, sub = int(m.param2), int(m.param3)
            hold, resume = (main, sub) == (4, 3), (main, sub) == (4, 4)
        if hold and self.flying:
            self.mission_running = False
            self.holding = True
        elif resume and self.armed and self.mission:
            self.mission_running = self.flying = True
            self.holding = False
        return int(mavlink.MAV_RESULT_ACCEPTED)

    def _autopilot_version(self) -> None:
        caps = (
            mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        )
        self._send(
            self.mav.autopilot_version_encode(
                caps,
                0x01_0F_00_FF,
                0,
                0,
                0,
                b"\0" * 8,
                b"\0" * 8,
                b"\0" * 8,
                0,
                0,
                self.sysid,
                [0] * 18,
            ),
            reply=True,
        )

    def _home_position(self) -> None:
        lat, lon, alt = self.home
        self._send(
            self.mav.home_position_encode(
                round(lat * 1e7),
                round(lon * 1e7),
                round(alt * 1000),
                0,
                0,
                0,
                [1, 0, 0, 0],
                0,
                0,
                0,
                0,
            ),
            reply=True,
        )

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

    def _step(self, dt: float) -> None:
        f = self.flight
        target = None
        if self.mission_running and self.current < len(self.mission):
            if self.ardupilot and self.current == 0:  # home is not flown to
                self.current = 1
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
            self.lat, self.lon = _moved(self.lat, self.lon, north * step / dist, east * step / dist)
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
        self._send(self.mav.mission_item_reached_encode(self.current))
        if item.command in (NAV_LAND, NAV_RETURN_TO_LAUNCH):
            self.alt, self.armed = 0.0, False
            self.mission_running = self.flying = self._rtl_descending = False
        elif self.current + 1 < len(self.mission):
            self.current += 1
        else:
            self.mission_running = False  # end of the mission: hold position (PX4: loiter)
        self._send(self.mav.mission_current_encode(self.current, len(self.mission), 0, 0))

    def take_off(self) -> None:
        """Armed, flying the mission from the current item (what arm + MISSION_START do)."""
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
