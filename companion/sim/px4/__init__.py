"""Real PX4 v1.16 SITL vehicles (SIH simulator, headless) for tests and scripted replays.

Simulation side, not product code.  :func:`find_build` checks a PX4 build (``bin/px4``,
``etc/``); :class:`Px4Vehicle` runs one instance of it in lock-step at a chosen speed factor
and talks to it as a ground station would over PX4's GCS link (pymavlink on an asyncio
datagram endpoint): mission upload, download and clear, MISSION_CURRENT, commands (arm,
mission start), and telemetry recorded as a trajectory in simulated time.  Modules: ``build``
(builds, instances, ports), ``link`` (the GCS link: telemetry, commands), ``missions`` (the
mission protocol), ``vehicle`` (the px4 process).
"""

from companion.sim.px4.build import MissionRefused, Px4Build, Px4Error, find_build, free_instance
from companion.sim.px4.vehicle import HEADLESS_PARAMS, HOME, Px4Vehicle

__all__ = [
    "HEADLESS_PARAMS",
    "HOME",
    "MissionRefused",
    "Px4Build",
    "Px4Error",
    "Px4Vehicle",
    "find_build",
    "free_instance",
]
