"""Real PX4 v1.16 SITL vehicles (SIH simulator, headless) for tests and scripted replays.

:class:`Px4Vehicle` runs one instance of a build (:mod:`.build`) in lock-step at a chosen
speed factor, from a fresh working directory, with the parameters a vehicle needs to fly
without RC or a ground station, and talks to it as a ground station would (:mod:`.link`,
:mod:`.missions`).  The product side (:mod:`companion.mission.autopilot`) talks to the same vehicle
over the onboard link at :attr:`Px4Vehicle.api_url`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import re
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

import companion.sim.px4.build as instances
from companion.sim.px4.build import (
    ALREADY_RUNNING,
    COMPANION_PORT,
    GCS_PORT,
    START_TRIES,
    Px4Build,
    Px4Error,
    end_group,
    find_build,
    free_instance,
)
from companion.sim.px4.link import GcsLink, result_name
from companion.sim.px4.missions import Px4Missions
from companion.tasks import spawn

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
log = logging.getLogger(__name__)


class Px4Vehicle(Px4Missions):
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
        super().__init__(gcs=gcs)
        self.build = build if isinstance(build, Px4Build) else find_build(build)
        self._requested_instance = instance
        self.home = home
        self.speed_factor = speed_factor
        self.model = model
        self.params = {**HEADLESS_PARAMS, **({} if ulog else NO_LOG_PARAMS), **(params or {})}
        self.ready_timeout_s = ready_timeout_s
        self.workdir: Path | None = None
        self._log: Any = None
        self._heartbeat_task: asyncio.Task[None] | None = None

    @property
    def api_url(self) -> str:
        """Where the companion (MAVSDK) listens for this vehicle's onboard link."""
        return f"udpin://127.0.0.1:{COMPANION_PORT + self.instance}"

    @property
    def gcs_port(self) -> int:
        return GCS_PORT + self.instance

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
            instances.claim(self.instance)
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
                instances.mark_taken(self.instance)
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
        instances.running(self._process.pid, self.workdir)
        loop = asyncio.get_running_loop()
        _, self._link = await loop.create_datagram_endpoint(
            lambda: GcsLink(("127.0.0.1", self.gcs_port), self._on_message),
            local_addr=("127.0.0.1", 0),
        )
        self._heartbeat_task = spawn(
            self._heartbeats(), name=f"px4-{self.instance}-heartbeats", log=log
        )
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
                    result_name(result),
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
            await end_group(process)
            instances.stopped(process.pid)
        if self._log is not None:
            self._log.close()
            self._log = None
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)
            self.workdir = None
        instances.release(self.instance)

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


def _param_text(value: int | float) -> str:
    return str(value) if isinstance(value, int) else repr(float(value))
