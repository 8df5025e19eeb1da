"""A ground station's MAVLink link to a PX4 SITL vehicle: telemetry and commands.

pymavlink on an asyncio datagram endpoint to PX4's GCS port: HEARTBEATs from our side, the
vehicle's messages kept (the latest of each type, the position track in simulated time, the
mission state), COMMAND_LONG with its COMMAND_ACK, and waiting for a condition on them.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import Counter, deque
from collections.abc import AsyncIterator, Callable
from typing import Any, cast

from pymavlink.dialects.v20 import common as mavlink

from companion.sim.mock_links import parse_datagram
from companion.sim.px4.build import Px4Error

# PX4 custom_mode in HEARTBEAT: main mode in bits 16-23, sub mode in 24-31
PX4_MODE_AUTO, PX4_AUTO_LOITER, PX4_AUTO_MISSION = 4, 3, 4

MISSION_STATE_COMPLETE = 5  # MISSION_CURRENT.mission_state (PX4 v1.16 sends 0)

LANDED_ON_GROUND, LANDED_IN_AIR = (
    mavlink.MAV_LANDED_STATE_ON_GROUND,
    mavlink.MAV_LANDED_STATE_IN_AIR,
)

FINISHED_HOVER_S = 2.0  # simulated seconds at the reached last item before a flight is over

STEP_S, TRIES = 0.5, 8  # our side of the mission protocol: wait per message, attempts


class GcsLink(asyncio.DatagramProtocol):
    """A ground station's UDP socket: sends to PX4's GCS port, parses what comes back."""

    def __init__(self, peer: tuple[str, int], on_message: Callable[[Any], None]) -> None:
        self.peer = peer
        self.on_message = on_message
        self.mav = mavlink.MAVLink(
            None, srcSystem=255, srcComponent=mavlink.MAV_COMP_ID_MISSIONPLANNER
        )
        self.mav.robust_parsing = True
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if addr[1] != self.peer[1]:
            return
        for message in parse_datagram(self.mav, data):
            self.on_message(message)

    def error_received(self, exc: Exception) -> None:
        pass  # ICMP port unreachable before PX4 binds its port

    def send(self, message: Any) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        data = message.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.transport.sendto(data, self.peer)


class Px4Link:
    """What a ground station knows of and can tell one PX4 vehicle (its system id is the
    vehicle's instance + 1)."""

    def __init__(self, *, gcs: bool) -> None:
        self.instance = -1  # the vehicle's, once started
        self.gcs = gcs
        self.trajectory: list[tuple[float, float, float, float]] = []  # (sim s, lat, lon, AMSL)
        self.last: dict[str, Any] = {}  # the latest message of each type from the autopilot
        self.mission_current: int | None = None  # MISSION_CURRENT.seq
        self.mission_total: int | None = None  # PX4 says 65535 while it holds no mission
        self.mission_state: int | None = None  # MISSION_STATE (PX4 v1.16 leaves it 0)
        self.reached: int | None = None  # the latest MISSION_ITEM_REACHED.seq
        self.received: Counter[str] = Counter()  # messages from the autopilot, by type
        self.statustexts: deque[str] = deque(maxlen=200)
        self.last_transfer: list[str] = []  # message types PX4 sent in the last transfer
        self.has_been_armed = False
        self._hovering_since: float | None = None  # at the reached last item
        self._process: asyncio.subprocess.Process | None = None  # px4, run by the vehicle
        self._link: GcsLink | None = None
        self._inboxes: list[tuple[frozenset[str], asyncio.Queue[Any]]] = []
        self._changed = asyncio.Event()
        self._transfer = asyncio.Lock()

    @property
    def system_id(self) -> int:
        return self.instance + 1

    def _on_message(self, m: Any) -> None:
        if m.get_srcSystem() != self.system_id or m.get_srcComponent() != 1:
            return
        name = m.get_type()
        self.last[name] = m
        self.received[name] += 1
        if name == "GLOBAL_POSITION_INT":
            self.trajectory.append((m.time_boot_ms / 1000, m.lat / 1e7, m.lon / 1e7, m.alt / 1000))
        elif name == "MISSION_CURRENT":
            self.mission_current, self.mission_total = int(m.seq), int(m.total)
            self.mission_state = int(m.mission_state)
        elif name == "MISSION_ITEM_REACHED":
            self.reached = int(m.seq)
        elif name == "HEARTBEAT" and self.armed:
            self.has_been_armed = True
        elif name == "STATUSTEXT":
            self.statustexts.append(str(m.text))
        if not self.mission_finished or self.landed_state != LANDED_IN_AIR:
            self._hovering_since = None
        elif self._hovering_since is None:
            self._hovering_since = self.sim_time_s
        for types, inbox in self._inboxes:
            if name in types:
                inbox.put_nowait(m)
        self._changed.set()

    @property
    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return hb is not None and bool(hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def mode(self) -> tuple[int, int]:
        """PX4 (main mode, sub mode), e.g. (4, 4) AUTO.MISSION, (4, 3) AUTO.LOITER."""
        hb = self.last.get("HEARTBEAT")
        custom = 0 if hb is None else int(hb.custom_mode)
        return (custom >> 16) & 0xFF, (custom >> 24) & 0xFF

    @property
    def landed(self) -> bool:
        state = self.last.get("EXTENDED_SYS_STATE")
        return state is not None and state.landed_state == LANDED_ON_GROUND

    @property
    def mission_running(self) -> bool:
        """Armed in AUTO.MISSION with the last item not reached yet."""
        mission_mode = self.mode == (PX4_MODE_AUTO, PX4_AUTO_MISSION)
        return self.armed and mission_mode and not self.mission_finished

    @property
    def landed_state(self) -> int:
        """MAV_LANDED_STATE from EXTENDED_SYS_STATE (0 until the first one)."""
        state = self.last.get("EXTENDED_SYS_STATE")
        return 0 if state is None else int(state.landed_state)

    @property
    def mission_finished(self) -> bool:
        """The last item is current and reached (PX4 v1.16 leaves MISSION_CURRENT's
        mission_state 0; it reports a LAND item reached when the descent starts)."""
        total, current = self.mission_total, self.mission_current
        if self.mission_state == MISSION_STATE_COMPLETE:
            return True
        return bool(total) and self.reached == current == (total or 0) - 1

    @property
    def finished(self) -> bool:
        """Done flying: landed and disarmed after having been armed, or hovering at the reached
        last item of its mission for FINISHED_HOVER_S (simulated)."""
        if self.has_been_armed and self.landed and not self.armed:
            return True
        since = self._hovering_since
        return since is not None and self.sim_time_s - since >= FINISHED_HOVER_S

    @property
    def position(self) -> tuple[float, float, float] | None:
        """The latest (lat, lon, alt AMSL)."""
        return self.trajectory[-1][1:] if self.trajectory else None

    @property
    def sim_time_s(self) -> float:
        """Simulated seconds since boot (time_boot_ms of the latest position)."""
        return self.trajectory[-1][0] if self.trajectory else 0.0

    async def wait_until(self, condition: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Wait (real time) until ``condition()`` holds; Px4Error on timeout or if px4 died."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while not condition():
            process = self._process
            if process is None or process.returncode is not None:
                code = None if process is None else process.returncode
                raise Px4Error(f"px4 exited ({code}) while waiting for {what}")
            remaining = deadline - loop.time()
            if remaining <= 0:
                raise Px4Error(f"timed out after {timeout_s} s waiting for {what}")
            self._changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._changed.wait(), min(remaining, 0.2))

    async def wait_finished(self, timeout_s: float) -> None:
        await self.wait_until(lambda: self.finished, timeout_s, "the end of the flight")

    def send(self, message: Any) -> None:
        """Send any MAVLink message (built with :attr:`mav`) to PX4's GCS link."""
        if self._link is None:
            raise Px4Error("not started")
        self._link.send(message)

    @property
    def mav(self) -> Any:
        """The pymavlink encoder of our (ground station's) side, for :meth:`send`."""
        if self._link is None:
            raise Px4Error("not started")
        return self._link.mav

    async def _heartbeats(self) -> None:
        """1 Hz HEARTBEAT: PX4's GCS link then talks to us.  As a ground station, or (``gcs``
        False) as an onboard controller, which PX4 does not count as a ground station."""
        kind = mavlink.MAV_TYPE_GCS if self.gcs else mavlink.MAV_TYPE_ONBOARD_CONTROLLER
        while True:
            self.send(
                self.mav.heartbeat_encode(
                    kind,
                    mavlink.MAV_AUTOPILOT_INVALID,
                    0,
                    0,
                    mavlink.MAV_STATE_ACTIVE,
                )
            )
            await asyncio.sleep(1.0)

    @contextlib.asynccontextmanager
    async def listen(self, *types: str) -> AsyncIterator[asyncio.Queue[Any]]:
        """A queue of the autopilot's messages of ``types``, while the context is open."""
        entry = (frozenset(types), asyncio.Queue[Any]())
        self._inboxes.append(entry)
        try:
            yield entry[1]
        finally:
            self._inboxes.remove(entry)

    async def _exchange(
        self,
        inbox: asyncio.Queue[Any],
        send: Callable[[], None],
        accept: Callable[[Any], bool | None],
    ) -> Any:
        """Send, then the first message ``accept`` takes (True; None: progress, wait on);
        re-sent after STEP_S without progress, TRIES times."""
        loop = asyncio.get_running_loop()
        tries = 0
        while tries < TRIES:
            send()
            tries += 1
            deadline = loop.time() + STEP_S
            while (remaining := deadline - loop.time()) > 0:
                try:
                    message = await asyncio.wait_for(inbox.get(), remaining)
                except TimeoutError:
                    break
                verdict = accept(message)
                if verdict:
                    return message
                if verdict is None:
                    tries, deadline = 0, loop.time() + STEP_S
        raise Px4Error(f"no answer from PX4 after {TRIES} tries")

    async def command(self, command: int, *params: float, timeout_s: float = 5.0) -> int:
        """COMMAND_LONG; the final MAV_RESULT of its COMMAND_ACK."""
        p = [*params, *[0.0] * (7 - len(params))]
        loop = asyncio.get_running_loop()
        async with self.listen("COMMAND_ACK") as inbox:
            for confirmation in range(TRIES):
                self.send(
                    self.mav.command_long_encode(self.system_id, 1, command, confirmation, *p)
                )
                deadline = loop.time() + timeout_s / TRIES
                while (remaining := deadline - loop.time()) > 0:
                    try:
                        ack = await asyncio.wait_for(inbox.get(), remaining)
                    except TimeoutError:
                        break
                    if ack.command != command:
                        continue
                    if ack.result != mavlink.MAV_RESULT_IN_PROGRESS:
                        return int(ack.result)
                    deadline = loop.time() + timeout_s  # in progress: wait for the result
        raise Px4Error(f"no COMMAND_ACK for command {command} within {timeout_s} s")

    async def set_mode(self, main: int, sub: int) -> None:
        """MAV_CMD_DO_SET_MODE to PX4's (main, sub) mode, as MAVSDK's pause and start do."""
        flag = float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        result = await self.command(mavlink.MAV_CMD_DO_SET_MODE, flag, float(main), float(sub))
        if result != mavlink.MAV_RESULT_ACCEPTED:
            raise Px4Error(f"mode ({main}, {sub}) refused ({result_name(result)})")

    async def take_off(self, first_item: int = 0, timeout_s: float = 10.0) -> None:
        """Start the mission at ``first_item``: MAV_CMD_MISSION_START, which on PX4 switches to
        AUTO.MISSION and arms; then wait until armed.  Repeated while PX4 denies it ("No valid
        mission": its feasibility check runs a moment after an upload)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while True:
            result = await self.command(mavlink.MAV_CMD_MISSION_START, float(first_item), -1.0)
            if result == mavlink.MAV_RESULT_ACCEPTED:
                break
            if result != mavlink.MAV_RESULT_DENIED or loop.time() > deadline:
                raise Px4Error(
                    f"MISSION_START refused ({result_name(result)}): "
                    f"{[text.strip() for text in self.statustexts][-3:]}"
                )
            await asyncio.sleep(0.1)
        await self.wait_until(lambda: self.armed, timeout_s, "the vehicle to arm")


def result_name(result: int) -> str:
    entry = mavlink.enums["MAV_RESULT"].get(result)
    return entry.name if entry is not None else str(result)
