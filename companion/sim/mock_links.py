"""The UDP links of the mock autopilot, opened as PX4 SITL opens them, and its wire faults.

PX4 instance i has an API/onboard link (binds 14580 + i, sends to 14540 + i, where MAVSDK
listens) and a GCS link (binds 18570 + i, sends to 14550, where QGroundControl listens).  Each
link sends to its configured port until the first datagram arrives and then to that
datagram's sender for good (measured on PX4 v1.16: a second ground station that talks to the
same link is heard but never answered, and takes nothing away from the first).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

from pymavlink.dialects.v20 import common as mavlink

PX4_BIND, PX4_SEND = 14580, 14540  # API/onboard link of instance 0
PX4_GCS_BIND, PX4_GCS_SEND = 18570, 14550  # GCS link of instance 0 (sends to 14550 for all)


def parse_datagram(mav: Any, data: bytes) -> list[Any]:
    """The MAVLink messages of one UDP datagram; garbage yields none."""
    try:
        messages = mav.parse_buffer(data) or []
    except mavlink.MAVError:
        return []
    return [m for m in messages if m.get_type() != "BAD_DATA"]


@dataclass(frozen=True)
class Faults:
    """Fault injection: every field off by default."""

    drop_every: int = 0  # drop every k-th mission-protocol reply
    latency_s: float = 0.0  # added to every reply
    ignore: frozenset[str] = frozenset()  # MAVLink message names to ignore, e.g. MISSION_COUNT
    reject_upload: int | None = None  # MAV_MISSION_RESULT to answer every upload with
    vanish_after_s: float | None = None  # stop answering and sending after this (real) time
    garble_uploads: int = 0  # store the next N uploads with the last item's altitude wrong


class Link(asyncio.DatagramProtocol):
    """One MAVLink 2 UDP link: its own parser, sequence numbers and partner.

    Sends to ``(host, send_port)`` until the first datagram arrives, then to its sender (the
    first partner is kept, as PX4 does).  Every parsed message goes to ``receive``.
    """

    def __init__(
        self,
        name: str,
        host: str,
        bind_port: int,
        send_port: int,
        sysid: int,
        receive: Callable[[Link, Any], None],
    ) -> None:
        self.name = name
        self.host = host
        self.bind_port = bind_port
        self.send_port = send_port
        self.partner: tuple[str, int] = (host, send_port)
        self.partnered = False  # a partner contacted the link (and is kept)
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
        self.mav.robust_parsing = True
        self._receive = receive
        self._transport: asyncio.DatagramTransport | None = None

    def __repr__(self) -> str:
        return f"Link({self.name} {self.host}:{self.bind_port} -> {self.partner})"

    async def open(self) -> None:
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(lambda: self, local_addr=(self.host, self.bind_port))

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()

    @property
    def is_open(self) -> bool:
        return self._transport is not None and not self._transport.is_closing()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if not self.partnered:
            self.partner, self.partnered = addr, True
        for message in parse_datagram(self.mav, data):
            self._receive(self, message)

    def send(self, message: Any, delay_s: float = 0.0) -> None:
        """Pack ``message`` with this link's sequence number and send it to the partner."""
        if not self.is_open:
            return
        data = message.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        if delay_s > 0:
            asyncio.get_running_loop().call_later(delay_s, self._sendto, data)
        else:
            self._sendto(data)

    def _sendto(self, data: bytes) -> None:
        if self._transport is not None and not self._transport.is_closing():
            self._transport.sendto(data, self.partner)


def heartbeat(
    mav: Any, ardupilot: bool, armed: bool, in_mission: bool, holding: bool = False
) -> Any:
    """HEARTBEAT of a quadrotor in its custom mode: flying the mission, PX4's AUTO.MISSION
    (main 4, sub 4) or ArduPilot Copter's AUTO (3); holding in the air (paused, or the
    mission over), AUTO.LOITER (4, 3) or LOITER (5); else PX4 0, ArduPilot STABILIZE (0)."""
    autopilot = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA if ardupilot else mavlink.MAV_AUTOPILOT_PX4
    base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if armed:
        base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    if in_mission:
        custom = 3 if ardupilot else (4 << 16) | (4 << 24)
    elif holding:
        custom = 5 if ardupilot else (4 << 16) | (3 << 24)
    else:
        custom = 0
    state = mavlink.MAV_STATE_ACTIVE if armed else mavlink.MAV_STATE_STANDBY
    return mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, autopilot, base, custom, state, 3)


def autopilot_version(mav: Any, sysid: int) -> Any:
    """AUTOPILOT_VERSION: MISSION_INT and MAVLink 2 capable, version 1.15.0."""
    caps = mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    no_hash = b"\0" * 8
    return mav.autopilot_version_encode(
        caps, 0x01_0F_00_FF, 0, 0, 0, no_hash, no_hash, no_hash, 0, 0, sysid, [0] * 18
    )


def home_position(mav: Any, home: tuple[float, float, float]) -> Any:
    """HOME_POSITION of (lat, lon degrees, alt AMSL metres)."""
    lat, lon, alt = home
    return mav.home_position_encode(
        round(lat * 1e7), round(lon * 1e7), round(alt * 1000), 0, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0
    )
