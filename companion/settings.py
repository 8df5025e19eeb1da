"""A companion's settings and credentials: what the config file and the command line give
(:mod:`companion.app.config` loads them; the defaults here are the only ones)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from companion.auth.session import Identity
from companion.auth.trust import TrustStore
from companion.mission.planner import OffsetSettings
from companion.mission.schedule import SeparationSettings
from companion.runs.failsafe import FailsafeSettings
from protocol.messages import Suite
from protocol.ot.setup import DEFAULT_SECURITY


@dataclass(frozen=True)
class CompanionSettings:
    node: int
    autopilot_url: str
    autopilot_connect_s: float = 10.0  # no autopilot heard on the URL this long: an error
    ardupilot: bool = False
    suite: Suite = Suite.COMPACT
    ot_security: int = DEFAULT_SECURITY  # kappa of the OT setups we start (as Alice)
    offset: OffsetSettings = field(default_factory=OffsetSettings)
    beacon_interval_s: float = 10.0
    initiation_range_m: float = 5000.0
    grid_resolution_mm: int = 2000  # 2 m cells: 15 m separation is 9 (docs/companion.md)
    grid_radius_m: float = 500.0  # smallest comparison box; doubled until it holds Alice's path
    max_box_radius_m: float = 64000.0  # largest box we answer in (as Bob): 40 m/s for 27 min
    # Farthest from us a requester's box may be centred (as Bob): a drone we hear on a LoRa
    # radio (km to tens of km), not a claim 50 km off.
    max_peer_range_m: float = 30000.0
    min_grid_resolution_mm: int = 100  # finest grid we answer on (as Bob)
    max_runs_per_peer: int = 8  # runs a certified drone may ask of us per window
    max_runs_total: int = 64  # runs all peers together may ask of us per window
    max_answer_bits_per_peer: int = 256  # answer bits (segments x runs) one drone may get
    run_window_s: float = 3600.0
    max_clock_skew_s: float = 30.0  # beacons and run requests further off our clock: refused
    run_timeout_s: float | None = 900.0  # a run's time limit (None: none)
    retry_after_s: float = 30.0
    busy_retry_s: tuple[float, float] = (5.0, 15.0)  # a peer busy with its own run: retry
    # after a random wait in this range (drones refused by one busy peer do not all return
    # at once)
    lookahead_s: float = 60.0  # the near run covers at least this much flight (0: no near run)
    cruise_m_s: float = 10.0  # MPC_XY_CRUISE: the flight model's speed until the mission's own
    failsafe: FailsafeSettings = field(default_factory=FailsafeSettings)
    separation: SeparationSettings = field(default_factory=SeparationSettings)


@dataclass(frozen=True)
class Credentials:
    """Who the companion is (its key and its operator's certificate), whom it deconflicts
    with (the trust store) and where it keeps what must survive a restart."""

    identity: Identity
    trust: TrustStore
    state_dir: Path
