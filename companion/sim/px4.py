"""Real PX4 v1.16 SITL vehicles (SIH simulator, headless) for tests and scripted replays.

Simulation side, not product code.  :func:`find_build` checks a PX4 build (``bin/px4``,
``etc/``); :class:`Px4Vehicle` runs one instance of it in lock-step at a chosen speed factor,
from a fresh working directory, with the parameters a vehicle needs to fly without RC or a
ground station, and talks to it as a ground station would over PX4's GCS link (pymavlink on
an asyncio datagram endpoint): mission upload, download and clear, MISSION_CURRENT, commands
(arm, mission start), and telemetry recorded as a trajectory in simulated time.  The product
side (:mod:`companion.autopilot`) talks to the same vehicle over the onboard link at
:attr:`Px4Vehicle.api_url`.

Ports of instance i (PX4 binds all but 14540 + i): GCS link 18570 + i, onboard link 14580 + i
sending to 14540 + i (the companion), and 14280 + i, 13030 + i, 19450 + i.  System id i + 1.
"""

from __future__ import annotations

import asyncio
import atexit
import contextlib
import errno
import fcntl
import logging
import os
import re
import shutil
import signal
import socket
import tempfile
from collections import Counter, deque
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from pymavlink.dialects.v20 import common as mavlink

from ..mission import MissionItem
from .mock_links import parse_datagram
from .mock_missions import item_from, item_message

GCS_PORT, ONBOARD_PORT, COMPANION_PORT = 18570, 14580, 14540
PORT_BASES = (GCS_PORT, ONBOARD_PORT, COMPANION_PORT, 14280, 13030, 19450)
INSTANCES = range(1, 40)  # 14540 + 39 is the last port below the onboard link's 14580
HOME = (47.3990, 8.5420, 488.0)  # lat, lon (degrees), altitude AMSL (m)
READY_LINE = "Ready for takeoff!"

# Flying without RC or a ground station (measured on PX4 v1.16.0 SITL: see
# docs/px4-sitl-findings.md).  Applied through PX4_PARAM_<name> in the environment, which the
# start-up script sets before any flight module starts.
HEADLESS_PARAMS: dict[str, int | float] = {
    "NAV_DLL_ACT": 0,  # no action on GCS data-link loss
    "NAV_RCL_ACT": 0,  # no action on RC loss
    "COM_RCL_EXCEPT": 1,  # ... and none in mission mode
    "COM_RC_IN_MODE": 4,  # no RC or joystick expected
    "COM_DISARM_PRFLT": -1.0,  # do not disarm between arming and the mission start
    "MIS_TAKEOFF_ALT": 30.0,
    "MPC_XY_CRUISE": 10.0,
}
TRACK_HZ = 10.0  # GLOBAL_POSITION_INT on our link, per simulated second
# message id -> Hz on our link (0: off); the rest keep PX4's "normal" GCS rates
QUIET_STREAMS: dict[int, float] = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE_TARGET: 0,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 0,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: TRACK_HZ,
}
NO_LOG_PARAMS: dict[str, int | float] = {"SDLOG_MODE": -1}  # no .ulg (about 4 MB/s at 10x)

# PX4 custom_mode in HEARTBEAT: main mode in bits 16-23, sub mode in 24-31
PX4_MODE_AUTO, PX4_AUTO_MISSION = 4, 4
MISSION_STATE_COMPLETE = 5  # MISSION_CURRENT.mission_state (PX4 v1.16 sends 0)
LANDED_ON_GROUND, LANDED_IN_AIR = (
    mavlink.MAV_LANDED_STATE_ON_GROUND,
    mavlink.MAV_LANDED_STATE_IN_AIR,
)
FINISHED_HOVER_S = 2.0  # simulated seconds at the reached last item before a flight is over
ACCEPTED = mavlink.MAV_MISSION_ACCEPTED
STEP_S, TRIES = 0.5, 8  # our side of the mission protocol: wait per message, attempts


class Px4Error(Exception):
    """The PX4 build or a SITL vehicle did not do what was asked."""


class MissionRefused(Px4Error):
    """PX4 answered a mission transfer with a MISSION_ACK other than ACCEPTED."""

    def __init__(self, result: int, what: str) -> None:
        self.result = result
        entry = mavlink.enums["MAV_MISSION_RESULT"].get(result)
        self.name = entry.name if entry is not None else str(result)
        super().__init__(f"{what}: PX4 answered {self.name}")


# ---------------------------------------------------------------------- the build


_LINK_DIRS: dict[Path, Path] = {}  # build root -> its directory of client links
_RUNNING: dict[int, Path] = {}  # process group of a px4 not stopped yet -> its working dir


def _clean_up_at_exit() -> None:
    """Links, and any px4 a caller never stopped (it would run on without us)."""
    for group, workdir in _RUNNING.items():
        with contextlib.suppress(ProcessLookupError):
            os.killpg(group, signal.SIGKILL)
        shutil.rmtree(workdir, ignore_errors=True)
    for path in _LINK_DIRS.values():
        shutil.rmtree(path, ignore_errors=True)
    _RUNNING.clear()
    _LINK_DIRS.clear()


atexit.register(_clean_up_at_exit)


@dataclass(frozen=True)
class Px4Build:
    """A PX4 SITL build: ``bin/px4`` (server and, by its name, every client) and ``etc/``."""

    root: Path

    @property
    def binary(self) -> Path:
        return self.root / "bin" / "px4"

    @property
    def etc(self) -> Path:
        return self.root / "etc"

    @property
    def links(self) -> Path:
        """A directory of ``px4`` and ``px4-<client>`` symlinks to :attr:`binary`.

        Copies of a build can lose the ``bin/px4-*`` symlinks (they become 3-byte text files
        saying "px4"), and the start-up script then fails ("px4-param: Permission denied").
        Made once per build in a temporary directory, removed at exit; put it first in PATH.
        """
        made = _LINK_DIRS.get(self.root)
        if made is not None and made.is_dir():
            return made
        links = Path(tempfile.mkdtemp(prefix="px4-links-"))
        for entry in sorted((self.root / "bin").iterdir()):
            if entry.name == "px4-alias.sh":
                shutil.copy2(entry, links / entry.name)
            elif entry.name.startswith("px4-"):
                (links / entry.name).symlink_to(self.binary)
        (links / "px4").symlink_to(self.binary)
        _LINK_DIRS[self.root] = links
        return links

    def client(self, name: str) -> Path:
        """The client ``px4-<name>`` (``param``, ``commander``, ...)."""
        path = self.links / f"px4-{name}"
        if not path.exists():
            raise Px4Error(f"this PX4 build has no client px4-{name}")
        return path


def find_build(path: str | os.PathLike[str]) -> Px4Build:
    """The PX4 build at ``path``, checked; :class:`Px4Error` says what is missing."""
    root = Path(path).expanduser().resolve()
    if not root.is_dir():
        raise Px4Error(f"PX4 build {root}: no such directory")
    build = Px4Build(root)
    if not build.binary.is_file() or not os.access(build.binary, os.X_OK):
        raise Px4Error(f"PX4 build {root}: bin/px4 is missing or not executable")
    if not (build.etc / "init.d-posix" / "rcS").is_file():
        raise Px4Error(f"PX4 build {root}: etc/init.d-posix/rcS is missing")
    return build


# ---------------------------------------------------------------------- instances

log = logging.getLogger(__name__)
_IN_USE: set[int] = set()  # instances this process runs (their ports are bound only later)
_TAKEN: set[int] = set()  # instances a px4 refused as "already running" (skipped from then on)
START_TRIES = 3
ALREADY_RUNNING = "PX4 server already running"


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("0.0.0.0", port))  # noqa: S104 -- clashes with binds on any address
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return False
            raise
    return True


def _px4_lock_free(instance: int) -> bool:
    """No running px4 holds /tmp/px4_lock-<instance> (it takes the lock at start)."""
    path = Path(tempfile.gettempdir()) / f"px4_lock-{instance}"
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    finally:
        os.close(fd)  # closing releases the lock we may have taken
    return True


def free_instance(start: int = 1) -> int:
    """An instance in 1..39, from ``start`` on, whose six UDP ports are all free right now and
    that this process does not run already."""
    for instance in range(max(start, INSTANCES.start), INSTANCES.stop):
        if instance in _IN_USE or instance in _TAKEN or not _px4_lock_free(instance):
            continue
        if all(_port_free(base + instance) for base in PORT_BASES):
            return instance
    raise Px4Error(f"no free PX4 SITL instance in {start}..{INSTANCES.stop - 1}")


# ---------------------------------------------------------------------- the GCS link


class _GcsLink(asyncio.DatagramProtocol):
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


# ---------------------------------------------------------------------- the vehicle


class Px4Vehicle:
    """One PX4 SITL vehicle: ``async with Px4Vehicle(build, home=...) as vehicle: ...``.

    ``instance`` None picks a free one.  ``params`` are set at start, over
    :data:`HEADLESS_PARAMS`; ``ulog`` keeps PX4's flight log (off: it writes megabytes a
    second at high speed factors); ``gcs`` False: our link does not pose as a ground station.
    """

    def __init__(
        self,
        build: Px4Build | str | os.PathLike[str],
        *,
        instance: int | None = None,
        home: tuple[float, float, float] = HOME,
        speed_factor: float = 10.0,
        model: str = "sihsim_quadx",
        params: Mapping[str, int | float] | None = None,
        ulog: bool = False,
        gcs: bool = True,
        ready_timeout_s: float = 60.0,
    ) -> None:
        self.build = build if isinstance(build, Px4Build) else find_build(build)
        self._requested_instance = instance
        self.instance = -1
        self.home = home
        self.speed_factor = speed_factor
        self.model = model
        self.params = {**HEADLESS_PARAMS, **({} if ulog else NO_LOG_PARAMS), **(params or {})}
        self.gcs = gcs
        self.ready_timeout_s = ready_timeout_s
        self.workdir: Path | None = None
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
        self._process: asyncio.subprocess.Process | None = None
        self._log: Any = None
        self._link: _GcsLink | None = None
        self._heartbeat_task: asyncio.Task[None] | None = None
        self._inboxes: list[tuple[frozenset[str], asyncio.Queue[Any]]] = []
        self._changed = asyncio.Event()
        self._transfer = asyncio.Lock()

    # ------------------------------------------------------------------ identity

    @property
    def system_id(self) -> int:
        return self.instance + 1

    @property
    def api_url(self) -> str:
        """Where the companion (MAVSDK) listens for this vehicle's onboard link."""
        return f"udpin://127.0.0.1:{COMPANION_PORT + self.instance}"

    @property
    def gcs_port(self) -> int:
        return GCS_PORT + self.instance

    # ------------------------------------------------------------------ lifecycle

    async def __aenter__(self) -> Px4Vehicle:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def start(self) -> None:
        """Start px4 and wait until it is ready for take-off and talks to us."""
        if self._process is not None:
            raise Px4Error("already started")
        for attempt in range(START_TRIES):
            self.instance = (
                free_instance() if self._requested_instance is None else self._requested_instance
            )
            _IN_USE.add(self.instance)
            try:
                await self._start()
                return
            except Px4Error as exc:
                await self.stop()
                # another px4 took the instance between our check and its start (or one
                # still shutting down holds its lock): try the next free one
                taken = ALREADY_RUNNING in str(exc) and self._requested_instance is None
                if not taken or attempt == START_TRIES - 1:
                    raise
                _TAKEN.add(self.instance)
            except BaseException:
                await self.stop()
                raise

    async def _start(self) -> None:
        self.workdir = Path(tempfile.mkdtemp(prefix=f"px4-sitl-{self.instance}-"))
        links = self.build.links
        lat, lon, alt = self.home
        env = {
            **os.environ,
            "PATH": f"{links}{os.pathsep}{os.environ.get('PATH', '')}",
            "PX4_SIM_MODEL": self.model,
            "PX4_SIM_SPEED_FACTOR": f"{self.speed_factor:g}",
            "PX4_HOME_LAT": f"{lat:.7f}",
            "PX4_HOME_LON": f"{lon:.7f}",
            "PX4_HOME_ALT": f"{alt:.2f}",
        }
        env.update({f"PX4_PARAM_{k}": _param_text(v) for k, v in self.params.items()})
        self._log = (self.workdir / "px4.log").open("wb")
        self._process = await asyncio.create_subprocess_exec(
            str(links / "px4"),
            "-i",
            str(self.instance),
            "-d",
            "-w",
            str(self.workdir),
            str(self.build.etc),
            stdin=asyncio.subprocess.DEVNULL,
            stdout=self._log,
            stderr=asyncio.subprocess.STDOUT,
            cwd=self.workdir,
            env=env,
            start_new_session=True,
        )
        _RUNNING[self._process.pid] = self.workdir
        loop = asyncio.get_running_loop()
        _, self._link = await loop.create_datagram_endpoint(
            lambda: _GcsLink(("127.0.0.1", self.gcs_port), self._on_message),
            local_addr=("127.0.0.1", 0),
        )
        self._heartbeat_task = asyncio.create_task(self._heartbeats())
        try:
            await self.wait_until(
                lambda: READY_LINE in self.log_text() and "HEARTBEAT" in self.last,
                self.ready_timeout_s,
                "PX4 to be ready for take-off",
            )
        except Px4Error as exc:
            raise Px4Error(f"{exc}; last lines of its log:\n{self.log_tail()}") from None
        await self._quiet_streams()

    async def _quiet_streams(self) -> None:
        """Ask PX4 to stop the high-rate streams of our link that nothing here reads (six
        of them at 50 Hz each, about 3000 messages a second of wall time at speed factor
        10, measured) and to send GLOBAL_POSITION_INT at :data:`TRACK_HZ`: parsing them
        all took a core's share two vehicles and their companions need.  Only load: a
        stream left on is logged, not fatal (under a busy machine an answer once took over
        5 s, right after start)."""
        for message_id, hz in QUIET_STREAMS.items():
            interval = -1.0 if hz == 0 else 1e6 / hz
            try:
                result = await self.command(
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, interval, timeout_s=15.0
                )
            except Px4Error as exc:
                log.warning("instance %d: stream %d left on: %s", self.instance, message_id, exc)
                continue
            if result != mavlink.MAV_RESULT_ACCEPTED:
                log.warning(
                    "instance %d: stream %d left on: %s",
                    self.instance,
                    message_id,
                    _result_name(result),
                )

    async def stop(self) -> None:
        """Stop px4 (its whole process group) and remove its working directory."""
        if self._heartbeat_task is not None:
            self._heartbeat_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._heartbeat_task
            self._heartbeat_task = None
        if self._link is not None and self._link.transport is not None:
            self._link.transport.close()
        self._link = None
        process, self._process = self._process, None
        if process is not None:
            await _end_group(process)
            _RUNNING.pop(process.pid, None)
        if self._log is not None:
            self._log.close()
            self._log = None
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)
            self.workdir = None
        _IN_USE.discard(self.instance)

    def log_text(self) -> str:
        """What px4 has printed so far."""
        if self.workdir is None:
            return ""
        try:
            return (self.workdir / "px4.log").read_text(errors="replace")
        except OSError:
            return ""

    def log_tail(self, lines: int = 25) -> str:
        return "\n".join(self.log_text().splitlines()[-lines:])

    # ------------------------------------------------------------------ clients

    async def run_client(self, name: str, *args: str, timeout_s: float = 10.0) -> str:
        """Run ``px4-<name> --instance i args...``; its output, or Px4Error when it fails."""
        process = await asyncio.create_subprocess_exec(
            str(self.build.client(name)),
            "--instance",
            str(self.instance),
            *args,
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT,
            env=self._client_env(),
        )
        try:
            out, _ = await asyncio.wait_for(process.communicate(), timeout_s)
        except TimeoutError:
            process.kill()
            await process.wait()
            raise Px4Error(f"px4-{name} {' '.join(args)}: no answer in {timeout_s} s") from None
        text = out.decode(errors="replace")
        if process.returncode != 0:
            raise Px4Error(f"px4-{name} {' '.join(args)} failed ({process.returncode}): {text}")
        return text

    def _client_env(self) -> dict[str, str]:
        return {**os.environ, "PATH": f"{self.build.links}{os.pathsep}{os.environ['PATH']}"}

    async def set_param(self, name: str, value: int | float) -> None:
        """``px4-param set``: takes effect at once for most parameters."""
        await self.run_client("param", "set", name, _param_text(value))

    async def param(self, name: str) -> str:
        """A parameter's value as ``px4-param show`` prints it."""
        out = await self.run_client("param", "show", name)
        found = re.search(rf"\s{re.escape(name)} \[[^]]*\] : (\S+)", out)
        if found is None:
            raise Px4Error(f"parameter {name} not found: {out.strip()}")
        return found.group(1)

    # ------------------------------------------------------------------ telemetry

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

    # ------------------------------------------------------------------ sending

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
                    f"MISSION_START refused ({_result_name(result)}): "
                    f"{[text.strip() for text in self.statustexts][-3:]}"
                )
            await asyncio.sleep(0.1)
        await self.wait_until(lambda: self.armed, timeout_s, "the vehicle to arm")

    # ------------------------------------------------------------------ missions

    async def upload_mission(
        self,
        items: Sequence[MissionItem],
        *,
        mission_type: int = 0,
        legacy: bool = False,
        count_zero: bool = False,
    ) -> None:
        """Upload ``items`` (sent as numbers 0..n-1, flags as given) with MISSION_ITEM_INT
        (``legacy``: MISSION_ITEM); an empty list clears with MISSION_CLEAR_ALL (``count_zero``:
        with MISSION_COUNT 0).  :class:`MissionRefused` unless PX4 acknowledges ACCEPTED."""
        if not items and not count_zero:
            await self.clear_mission(mission_type)
            return
        count = self.mav.mission_count_encode(self.system_id, 1, len(items), mission_type)
        last: list[Any] = [count]
        seen = self.last_transfer = []

        def accept(m: Any) -> bool | None:
            if m.mission_type != mission_type or m.target_system not in (0, 255):
                return False
            seen.append(m.get_type())
            if m.get_type() == "MISSION_ACK":
                return True
            if not 0 <= m.seq < len(items):
                return False
            # PX4 asks with MISSION_REQUEST until it has seen an INT message from us, and
            # takes MISSION_ITEM_INT in answer: the INT form unless ``legacy``
            item = items[m.seq].replace(seq=m.seq)
            reply = item_message(self.mav, self.system_id, 1, item, legacy=legacy)
            last[0] = reply
            self.send(reply)
            return None  # progress

        async with (
            self._transfer,
            self.listen("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK") as inbox,
        ):
            ack = await self._exchange(inbox, lambda: self.send(last[0]), accept)
        if ack.type != ACCEPTED:
            raise MissionRefused(int(ack.type), f"upload of {len(items)} items")

    async def clear_mission(self, mission_type: int = 0) -> None:
        """MISSION_CLEAR_ALL; MissionRefused unless acknowledged ACCEPTED."""
        clear = self.mav.mission_clear_all_encode(self.system_id, 1, mission_type)
        async with self._transfer, self.listen("MISSION_ACK") as inbox:
            ack = await self._exchange(
                inbox, lambda: self.send(clear), lambda m: m.mission_type == mission_type
            )
        if ack.type != ACCEPTED:
            raise MissionRefused(int(ack.type), f"clear (mission type {mission_type})")

    async def download_mission(
        self, *, mission_type: int = 0, legacy: bool = False
    ) -> list[MissionItem]:
        """The mission as PX4 sends it (frames, flags and params untouched), asked for with
        MISSION_REQUEST_INT (``legacy``: MISSION_REQUEST)."""
        seen = self.last_transfer = []
        items: list[MissionItem] = []
        types = ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_ACK")
        async with self._transfer, self.listen(*types) as inbox:

            def ours(m: Any) -> bool:
                if m.mission_type != mission_type or m.target_system not in (0, 255):
                    return False
                seen.append(m.get_type())
                return True

            def count(m: Any) -> bool:
                return ours(m) and m.get_type() in ("MISSION_COUNT", "MISSION_ACK")

            def item(m: Any) -> bool:
                if not ours(m) or m.get_type() == "MISSION_COUNT":
                    return False
                return m.get_type() == "MISSION_ACK" or bool(m.seq == len(items))

            request_list = self.mav.mission_request_list_encode(self.system_id, 1, mission_type)
            reply = await self._exchange(inbox, lambda: self.send(request_list), count)
            if reply.get_type() == "MISSION_ACK":
                raise MissionRefused(int(reply.type), "download")
            encode = (
                self.mav.mission_request_encode if legacy else self.mav.mission_request_int_encode
            )
            for seq in range(int(reply.count)):
                request = encode(self.system_id, 1, seq, mission_type)

                def send_request(request: Any = request) -> None:
                    self.send(request)

                message = await self._exchange(inbox, send_request, item)
                if message.get_type() == "MISSION_ACK":
                    raise MissionRefused(int(message.type), f"download of item {seq}")
                items.append(item_from(message, legacy=message.get_type() == "MISSION_ITEM"))
            self.send(self.mav.mission_ack_encode(self.system_id, 1, ACCEPTED, mission_type))
        return items

    async def set_current(self, seq: int, timeout_s: float = 5.0) -> None:
        """MISSION_SET_CURRENT, confirmed by MISSION_CURRENT."""
        message = self.mav.mission_set_current_encode(self.system_id, 1, seq)
        async with self.listen("MISSION_CURRENT") as inbox:
            await self._exchange(inbox, lambda: self.send(message), lambda m: m.seq == seq)


def _param_text(value: int | float) -> str:
    return str(value) if isinstance(value, int) else repr(float(value))


def _result_name(result: int) -> str:
    entry = mavlink.enums["MAV_RESULT"].get(result)
    return entry.name if entry is not None else str(result)


async def _end_group(process: asyncio.subprocess.Process, grace_s: float = 5.0) -> None:
    """SIGTERM to the process group (px4 shuts down cleanly), SIGKILL after ``grace_s``."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, sig)
        try:
            await asyncio.wait_for(process.wait(), grace_s)
            return
        except TimeoutError:
            continue
