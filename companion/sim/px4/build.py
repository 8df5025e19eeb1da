"""PX4 SITL builds and instances: where the binary is, which instance numbers are free.

:func:`find_build` checks a build (``bin/px4``, ``etc/``); :func:`free_instance` picks an
instance whose ports are all free and that no px4 holds.  Ports of instance i (PX4 binds all
but 14540 + i): GCS link 18570 + i, onboard link 14580 + i sending to 14540 + i (the
companion), and 14280 + i, 13030 + i, 19450 + i.  Whatever a caller leaves running is
stopped at exit.
"""

from __future__ import annotations

import asyncio
import atexit
import contextlib
import errno
import fcntl
import os
import shutil
import signal
import socket
import tempfile
from dataclasses import dataclass
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

from companion.errors import CompanionError

GCS_PORT, ONBOARD_PORT, COMPANION_PORT = 18570, 14580, 14540

PORT_BASES = (GCS_PORT, ONBOARD_PORT, COMPANION_PORT, 14280, 13030, 19450)

INSTANCES = range(1, 40)  # 14540 + 39 is the last port below the onboard link's 14580


class Px4Error(CompanionError):
    """The PX4 build or a SITL vehicle did not do what was asked."""


class MissionRefused(Px4Error):
    """PX4 answered a mission transfer with a MISSION_ACK other than ACCEPTED."""

    def __init__(self, result: int, what: str) -> None:
        self.result = result
        entry = mavlink.enums["MAV_MISSION_RESULT"].get(result)
        self.name = entry.name if entry is not None else str(result)
        super().__init__(f"{what}: PX4 answered {self.name}")


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


def claim(instance: int) -> None:
    """This process runs ``instance`` now (its ports are bound only later)."""
    _IN_USE.add(instance)


def release(instance: int) -> None:
    _IN_USE.discard(instance)


def mark_taken(instance: int) -> None:
    """A px4 refused ``instance`` as already running: skipped from now on."""
    _TAKEN.add(instance)


def running(group: int, workdir: Path) -> None:
    """A px4 process group to kill (and its directory to remove) at exit if never stopped."""
    _RUNNING[group] = workdir


def stopped(group: int) -> None:
    _RUNNING.pop(group, None)


def free_instance(start: int = 1) -> int:
    """An instance in 1..39, from ``start`` on, whose six UDP ports are all free right now and
    that this process does not run already."""
    for instance in range(max(start, INSTANCES.start), INSTANCES.stop):
        if instance in _IN_USE or instance in _TAKEN or not _px4_lock_free(instance):
            continue
        if all(_port_free(base + instance) for base in PORT_BASES):
            return instance
    raise Px4Error(f"no free PX4 SITL instance in {start}..{INSTANCES.stop - 1}")


async def end_group(process: asyncio.subprocess.Process, grace_s: float = 5.0) -> None:
    """SIGTERM to the process group (px4 shuts down cleanly), SIGKILL after ``grace_s``."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, sig)
        try:
            await asyncio.wait_for(process.wait(), grace_s)
            return
        except TimeoutError:
            continue
