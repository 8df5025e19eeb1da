"""The vehicle as the companion sees it: mission I/O and telemetry, through MAVSDK 4.1
(native asyncio API, ``mission_raw``, ``telemetry``).

:class:`AutopilotBase` is what the companion asks of an autopilot -- its mission (download,
replace, pause, resume), its home and four telemetry streams (position, armed, holding,
mission progress) -- with the one promise of a mission edit in one place; :class:`Autopilot`
does it over MAVSDK (a real vehicle, PX4 SITL, the mock autopilot over MAVLink), and
:class:`companion.sim.inproc.InProcessAutopilot` with a mock vehicle in the same process
(replays in virtual time).  Connect, download and normalise, upload and verify.  The one
promise: after :meth:`AutopilotBase.replace_mission` the vehicle holds either the new mission
or the old one, never a mix -- the upload is read back and compared item by item by what
the autopilot *means* (:meth:`companion.mission.personalities.Personality.same_meaning`: PX4 reads
frame 3 back as 6, wraps yaw, zeroes parameters it does not keep), and on any failure the
original is uploaded again (or, if the vehicle held none, the mission cleared) and read
back before the error is raised.  A mission the autopilot would refuse is refused before
anything is sent.  Read-backs wait ``settle_s`` after an upload and are retried (PX4
returns the previous mission to about 2.5 % of downloads 10 ms after an upload).  Every
call is bounded by a timeout; a silent or vanished autopilot is an :class:`AutopilotError`,
never a hang.
"""

from __future__ import annotations

import abc
import asyncio
import ipaddress
import logging
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.errors import CompanionError
from companion.mission.items import MissionError, MissionItem, normalise
from companion.mission.personalities import PX4, Personality
from companion.tasks import spawn

log = logging.getLogger(__name__)


class AutopilotError(CompanionError):
    """The autopilot did not do what was asked (timeout, refusal, mismatch)."""


class RolledBack(AutopilotError):
    """The edit failed; the vehicle was verified to hold its previous mission again."""


# The connection URLs MAVSDK 4 takes (its cli_arg.cpp); udp:// and tcp:// are its deprecated
# spellings of udpin:// and tcpout://.
URL_SCHEMES = ("udpin", "udpout", "udp", "tcpin", "tcpout", "tcp", "serial", "serial_flowcontrol")
# What MAVSDK's ConnectionResult names mean for someone who typed the URL.
_CONNECT_HINTS = {
    "SOCKET_ERROR": "is the address valid and one of this machine's?",
    "BIND_ERROR": "is the address one of this machine's, and the port free?",
    "SOCKET_CONNECTION_ERROR": "does anything listen at this address?",
    "DESTINATION_IP_UNKNOWN": "the host name does not resolve",
    "CONNECTION_ERROR": "is the device a serial port you may open?",
    "BAUDRATE_UNKNOWN": "use a standard baud rate such as 57600 or 115200",
    "CONNECTION_URL_INVALID": "see python -m companion run --help",
}


def check_url(url: str) -> str:
    """``url`` if MAVSDK can take it, else a ValueError saying what is wrong: a known scheme,
    then HOST:PORT with a port 1..65535 (an IP address for udpin/tcpin, which bind it) or
    DEVICE:BAUD with a device that exists.  Checked before anything starts, since MAVSDK
    itself says no more than ``CONNECTION_URL_INVALID``."""
    scheme, sep, rest = url.partition("://")
    if not sep or scheme not in URL_SCHEMES:
        raise ValueError(
            f"{url}: not a MAVSDK connection URL (schemes: {', '.join(URL_SCHEMES)}; e.g. "
            "udpin://0.0.0.0:14540 or serial:///dev/ttyACM0:57600)"
        )
    if scheme.startswith("serial"):
        device, sep, baud = rest.rpartition(":")
        if not sep or not device or not baud.isdigit() or int(baud) == 0:
            raise ValueError(f"{url}: expected {scheme}://DEVICE:BAUD (e.g. /dev/ttyACM0:57600)")
        if not Path(device).exists():
            raise ValueError(f"{url}: serial device {device} does not exist (is it plugged in?)")
        return url
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"{url}: expected {scheme}://HOST:PORT with a port 1..65535")
    if scheme in ("udpin", "tcpin"):
        try:
            ipaddress.ip_address(host)
        except ValueError:
            raise ValueError(
                f"{url}: {scheme} binds a local IP address, not {host!r} (0.0.0.0 for every "
                "interface, 127.0.0.1 for this machine only)"
            ) from None
    elif not host and scheme not in ("udp", "tcp"):
        raise ValueError(f"{url}: {scheme} needs the host to reach (e.g. 127.0.0.1)")
    return url


@dataclass(frozen=True, slots=True)
class Timeouts:
    connect_s: float = 10.0
    transfer_s: float = 30.0  # one download or upload (MAVSDK retries inside)
    retries: int = 2  # extra attempts of a failed transfer
    settle_s: float = 0.3  # between an upload and its read-back
    readbacks: int = 3  # read-backs before a difference counts


def to_mavsdk(item: MissionItem) -> Any:
    from mavsdk.asyncio.plugins.mission_raw import MissionItem as RawItem

    return RawItem(
        item.seq,
        item.frame,
        item.command,
        item.current,
        item.autocontinue,
        item.param1,
        item.param2,
        item.param3,
        item.param4,
        item.x,
        item.y,
        item.z,
        item.mission_type,
    )


def from_mavsdk(raw: Any) -> MissionItem:
    item = MissionItem(
        int(raw.seq),
        int(raw.frame),
        int(raw.command),
        int(raw.current),
        int(raw.autocontinue),
        float(raw.param1),
        float(raw.param2),
        float(raw.param3),
        float(raw.param4),
        int(raw.x),
        int(raw.y),
        float(raw.z),
        int(raw.mission_type),
    )
    item.check()
    return item


@dataclass(frozen=True, slots=True)
class Position:
    """One position report: degrees, metres above mean sea level and above home."""

    lat_deg: float
    lon_deg: float
    amsl_m: float
    relative_m: float


class AutopilotBase(abc.ABC):
    """What the companion asks of its vehicle.  Subclasses move missions and telemetry;
    :meth:`replace_mission` (upload, read back, restore on failure) is this class's."""

    def __init__(self, timeouts: Timeouts, personality: Personality) -> None:
        self.timeouts = timeouts
        self.personality = personality

    # -- what a vehicle link provides

    @abc.abstractmethod
    async def download(self) -> list[MissionItem]:
        """The vehicle's mission, normalised (seq 0..n-1, one current item)."""

    @abc.abstractmethod
    async def _upload(self, items: Sequence[MissionItem]) -> None: ...

    @abc.abstractmethod
    async def clear(self) -> None:
        """Remove the vehicle's mission."""

    @abc.abstractmethod
    async def home(self, timeout_s: float = 5.0) -> tuple[int, int, float] | None:
        """The vehicle's home (lat, lon degE7, alt AMSL), or None when it has none yet."""

    @abc.abstractmethod
    async def pause(self) -> None:
        """Hold position (PX4: AUTO.LOITER, ArduPilot: LOITER), the mission kept."""

    @abc.abstractmethod
    async def resume(self) -> None:
        """Continue the mission from the current item."""

    @abc.abstractmethod
    def positions(self, rate_hz: float) -> AsyncIterator[Position]:
        """Position reports, about ``rate_hz`` a second."""

    @abc.abstractmethod
    def armed_states(self) -> AsyncIterator[bool]:
        """Whether the vehicle is armed, on every change at least."""

    @abc.abstractmethod
    def holding_states(self) -> AsyncIterator[bool]:
        """Whether it holds in the air (paused, or its mission over): when it flies on is
        not known."""

    @abc.abstractmethod
    def progress(self) -> AsyncIterator[tuple[int, int]]:
        """Mission progress: (current item, items), on every change at least."""

    async def close(self) -> None:  # noqa: B027 -- optional: nothing to let go of by default
        """Let go of the vehicle."""

    async def __aenter__(self) -> AutopilotBase:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- the one promise of an edit

    def _matches(self, held: Sequence[MissionItem], sent: Sequence[MissionItem]) -> bool:
        same = self.personality.same_meaning
        return len(held) == len(sent) and all(same(b, a) for a, b in zip(held, sent, strict=True))

    async def _verify(self, items: Sequence[MissionItem]) -> bool:
        """Read back until the vehicle holds ``items`` (by meaning) or the tries are spent."""
        sent = normalise(items) if items else []
        for attempt in range(max(self.timeouts.readbacks, 1)):
            await asyncio.sleep(self.timeouts.settle_s * (attempt + 1))
            held = await self.download()
            if self._matches(held, sent):
                return True
        return False

    async def _put(self, items: Sequence[MissionItem]) -> bool:
        """Upload (an empty mission: clear) and verify."""
        if items:
            await self._upload(items)
        else:
            await self.clear()
        return await self._verify(items)

    async def replace_mission(
        self, new: Sequence[MissionItem], original: Sequence[MissionItem]
    ) -> None:
        """Upload ``new`` and verify it; on failure restore and verify ``original`` (an
        empty ``original``: the mission is cleared).  A mission the autopilot would refuse
        raises :class:`~companion.mission.personalities.UnsupportedItem` before anything is sent."""
        if not new:
            raise MissionError("refusing to upload an empty mission")
        if not any(it.current for it in new):  # MAVSDK would mark item 0: a restart
            raise MissionError("an upload must mark the item to continue at as current")
        new = normalise(new)
        self.personality.check(new)
        try:
            if await self._put(new):
                return
            problem: Exception = AutopilotError("read-back differs from the upload")
        except AutopilotError as exc:
            problem = exc
        log.warning("mission edit failed (%s); restoring the original", problem)
        try:
            restored = await self._put(original)
        except AutopilotError as exc:
            raise AutopilotError(
                f"edit failed ({problem}) and restoring the original failed too ({exc}); "
                "the vehicle's mission is unknown"
            ) from exc
        if not restored:
            raise AutopilotError(f"edit failed ({problem}); the restored mission differs")
        raise RolledBack(f"edit failed ({problem}); the vehicle holds its previous mission")


class Autopilot(AutopilotBase):
    """One vehicle over MAVSDK: ``async with Autopilot.connect("udpin://0.0.0.0:14540") as
    ap: ...``."""

    def __init__(
        self, mavsdk: Any, system: Any, timeouts: Timeouts, personality: Personality = PX4
    ) -> None:
        from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

        super().__init__(timeouts, personality)
        self._mavsdk = mavsdk
        self.system = system
        self.mission_raw = MissionRawAsync(system)

    @classmethod
    async def connect(
        cls, url: str, timeouts: Timeouts | None = None, personality: Personality = PX4
    ) -> Autopilot:
        """Connect to the first autopilot heard on ``url`` (checked by :func:`check_url`);
        MAVSDK's failures are an :class:`AutopilotError` that names the URL and a hint."""
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk, MavsdkError

        try:
            check_url(url)
        except ValueError as exc:
            raise AutopilotError(str(exc)) from None
        timeouts = timeouts or Timeouts()
        config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
        mavsdk = Mavsdk(config)
        await mavsdk.__aenter__()
        try:
            await mavsdk.add_any_connection(url)
            system = await mavsdk.first_autopilot(timeout_s=timeouts.connect_s)
        except MavsdkError as exc:
            await mavsdk.__aexit__(None, None, None)
            reason = str(exc).rpartition(": ")[2]  # "Connection failed: SOCKET_ERROR"
            hint = _CONNECT_HINTS.get(reason, "check the URL")
            raise AutopilotError(f"{url}: MAVSDK cannot connect: {reason} ({hint})") from exc
        except BaseException:
            await mavsdk.__aexit__(None, None, None)
            raise
        if system is None:
            await mavsdk.__aexit__(None, None, None)
            raise AutopilotError(f"no autopilot heard on {url} within {timeouts.connect_s} s")
        return cls(mavsdk, system, timeouts, personality)

    async def close(self) -> None:
        self.mission_raw.destroy()
        await self._mavsdk.__aexit__(None, None, None)

    async def __aenter__(self) -> Autopilot:
        return self

    async def positions(self, rate_hz: float) -> AsyncIterator[Position]:
        """GLOBAL_POSITION_INT.  PX4 sends it at 50 Hz on the onboard link (500 Hz in SITL at
        10x); a few a second is plenty and keeps MAVSDK's callbacks keeping up."""
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry = TelemetryAsync(self.system)

        async def set_rate() -> None:
            try:
                await asyncio.wait_for(telemetry.set_rate_position(rate_hz), 5.0)
            except Exception as exc:  # any MAVSDK error: keep the default rate
                log.info("position rate unchanged: %s", exc)

        # Positions flow while the rate is asked for: an autopilot that never answers the
        # request would otherwise hold the first position back 5 s (100 s of flight at 20x).
        rate = spawn(set_rate(), name="position-rate", log=log)
        try:
            async for p in telemetry.subscribe_position():
                yield Position(
                    float(p.latitude_deg),
                    float(p.longitude_deg),
                    float(p.absolute_altitude_m),
                    float(p.relative_altitude_m),
                )
        finally:
            rate.cancel()
            telemetry.destroy()

    async def armed_states(self) -> AsyncIterator[bool]:
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry = TelemetryAsync(self.system)
        try:
            async for armed in telemetry.subscribe_armed():
                yield bool(armed)
        finally:
            telemetry.destroy()

    async def holding_states(self) -> AsyncIterator[bool]:
        """MAVSDK's flight mode HOLD: PX4 AUTO.LOITER, ArduPilot LOITER."""
        from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

        telemetry = TelemetryAsync(self.system)
        try:
            async for mode in telemetry.subscribe_flight_mode():
                yield mode == FlightMode.HOLD
        finally:
            telemetry.destroy()

    async def progress(self) -> AsyncIterator[tuple[int, int]]:
        async for progress in self.mission_raw.subscribe_mission_progress():
            yield int(progress.current), int(progress.total)

    async def position(self, timeout_s: float = 5.0) -> tuple[float, float, float]:
        """The vehicle's latest (lat, lon, alt AMSL) from GLOBAL_POSITION_INT telemetry."""
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry = TelemetryAsync(self.system)
        try:
            stream = telemetry.subscribe_position()
            p = await asyncio.wait_for(anext(stream), timeout_s)
            await stream.aclose()
        except TimeoutError:
            raise AutopilotError(f"no position telemetry within {timeout_s} s") from None
        finally:
            telemetry.destroy()
        return float(p.latitude_deg), float(p.longitude_deg), float(p.absolute_altitude_m)

    async def home(self, timeout_s: float = 5.0) -> tuple[int, int, float] | None:
        """The vehicle's home (lat, lon degE7, alt AMSL) from HOME_POSITION, or None when the
        autopilot has not told it within ``timeout_s`` (no home set yet)."""
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        telemetry = TelemetryAsync(self.system)
        try:
            stream = telemetry.subscribe_home()
            h = await asyncio.wait_for(anext(stream), timeout_s)
            await stream.aclose()
        except TimeoutError:
            return None
        finally:
            telemetry.destroy()
        lat, lon = round(float(h.latitude_deg) * 1e7), round(float(h.longitude_deg) * 1e7)
        if (lat, lon) == (0, 0) or not (abs(lat) <= 900_000_000 and abs(lon) <= 1_800_000_000):
            return None
        return lat, lon, float(h.absolute_altitude_m)

    async def _call(self, what: str, call: Any) -> Any:
        from mavsdk.asyncio.plugins.mission_raw import MissionRawError

        last: Exception | None = None
        for attempt in range(1 + self.timeouts.retries):
            try:
                return await asyncio.wait_for(call(), self.timeouts.transfer_s)
            except (MissionRawError, TimeoutError) as exc:
                last = exc
                log.warning("%s failed (attempt %d): %s", what, attempt + 1, exc)
        raise AutopilotError(f"{what} failed: {last}") from last

    async def pause(self) -> None:
        """Hold position (PX4: AUTO.LOITER, ArduPilot: LOITER), the mission kept."""
        await self._call("mission pause", self.mission_raw.pause_mission)

    async def resume(self) -> None:
        """Continue the mission from the current item."""
        await self._call("mission start", self.mission_raw.start_mission)

    async def download(self) -> list[MissionItem]:
        """The vehicle's mission, normalised (seq 0..n-1, one current item)."""
        raw = await self._call("mission download", self.mission_raw.download_mission)
        try:
            return normalise([from_mavsdk(r) for r in raw]) if raw else []
        except MissionError as exc:
            raise AutopilotError(f"the vehicle holds an invalid mission: {exc}") from exc

    async def _upload(self, items: Sequence[MissionItem]) -> None:
        raw = [to_mavsdk(i) for i in items]
        await self._call("mission upload", lambda: self.mission_raw.upload_mission(raw))

    async def clear(self) -> None:
        """Remove the vehicle's mission (MISSION_CLEAR_ALL)."""
        await self._call("mission clear", self.mission_raw.clear_mission)
