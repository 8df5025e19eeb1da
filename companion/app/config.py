"""Settings of ``python -m companion run``: a TOML file, every key also a command-line flag.

::

    node = 1
    autopilot = "udpin://0.0.0.0:14540"   # MAVSDK URL; PX4 SITL instance i: 14540 + i
    autopilot_connect_s = 10.0            # no autopilot heard on it this long: an error
    ardupilot = false
    suite = "compact"                     # or "paper" (Paillier + DGK, the paper's design)
    ot_security = 112                     # compact suite, as Alice: 112 or 128-bit OT (Delta)
    log_level = "info"
    [link]
    transport = "udp"                     # "udp" (a link hub) or "serial" (a LoRa modem)
    profile = "us915-sf7"
    hub = "127.0.0.1:14600"
    serial = "/dev/ttyUSB0"
    baudrate = 115200
    [offset]
    offset_m = 10.0
    direction = "up"
    max_altitude_m = 120.0
    max_levels = 0                        # offsets above the plan at most, beyond them a hold
                                          # (0: raises go up to the ceiling, then a hold)
    [identity]                            # python -m companion keys init|certify
    key = "drone1.key"                    # this drone's signing key (paths: from this file)
    certificate = "drone1.cert"           # its operator's certificate (names this node)
    state_dir = "state1"                  # run budget, replay cache, beacon counters
    [trust]
    unknown_peers = "ignore"              # untrusted drones: "ignore" (logged once) or "alert"
    [[trust.operator]]                    # one per operator whose drones we deconflict with
    name = "acme"
    key = "acme.pub"                      # a PEM public key file, or 64 hex digits
    max_segments = 256                    # largest padded path of a run with its drones
    max_runs_per_hour = 24                # runs its drones together may ask of us
    max_answer_bits_per_hour = 1024       # answer bits its drones together may get of us
    paper_keys = false                    # suite "paper": we accept its drones' unproven keys
    [limits]
    max_runs_per_peer = 8                 # runs one certified drone may ask of us per hour
    max_runs_total = 64                   # runs all drones together may ask of us per hour
    max_answer_bits_per_peer = 256        # answer bits (segments of its runs) per drone per hour
    max_clock_skew_s = 30.0               # beacons and requests further off: refused
    run_timeout_s = 900.0
    beacon_interval_s = 10.0
    initiation_range_m = 5000.0
    lookahead_s = 60.0                    # compare at least the next 60 s of flight first
    grid_radius_m = 500.0                 # smallest comparison box (doubled to hold the path)
    max_box_radius_m = 64000.0            # largest box a peer's run may ask of us
    max_peer_range_m = 30000.0            # farthest a peer's box centre may be from us
    min_grid_resolution_mm = 100          # finest grid a peer's run may ask of us
    [failsafe]
    action = "climb"                      # "climb", "hold" or "off"
    margin_s = 10.0
    [separation]                          # what a conflict is (a run uses both drones' larger)
    horizontal_m = 15.0                   # segments closer than this, horizontally
    vertical_m = 10.0                     # altitude bands closer than this
    altitude_error_m = 1.0                # our own altitude uncertainty, either way
    late_s = 15.0                         # our own timing uncertainty: this much later
    early_s = 10.0                        # or this much earlier than predicted,
    time_tolerance_rate = 0.15            # plus this share of the time ahead either way
    # ground_wait_s = 600                 # on the ground: take-off within this long (then
                                          # compare again); absent: not known, windows open
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.app.tables import Table, TableError, load_toml
from companion.auth.certificate import Certificate, CertificateError
from companion.auth.keys import KeyFileError, PublicKey, read_private_key, read_public_key
from companion.auth.session import Identity
from companion.auth.trust import Operator, TrustStore, UnknownPeers
from companion.mission.autopilot import check_url
from companion.mission.planner import OffsetSettings
from companion.mission.schedule import SeparationSettings, Tolerance
from companion.radio.airtime import PROFILES
from companion.runs.failsafe import Action, FailsafeSettings
from companion.settings import CompanionSettings, Credentials
from protocol.messages import Suite
from protocol.ot.setup import SECURITY_LEVELS
from protocol.run import MAX_SEGMENTS

PROFILE_NAMES = tuple(PROFILES)
DEFAULT_AUTOPILOT = "udpin://0.0.0.0:14540"  # PX4 SITL instance 0's API link
# Every default is the settings' own (one place); tests check the example above says them.
BASE = CompanionSettings(node=1, autopilot_url=DEFAULT_AUTOPILOT)
TOLERANCE = BASE.separation.tolerance


class ConfigError(TableError):
    """The configuration is invalid; says which file and key."""


@dataclass(frozen=True)
class LinkSettings:
    transport: str = "udp"
    profile: str = "us915-sf7"
    hub: tuple[str, int] = ("127.0.0.1", 14600)
    serial: str = "/dev/ttyUSB0"
    baudrate: int = 115200


LINK = LinkSettings()


@dataclass(frozen=True)
class Config:
    companion: CompanionSettings
    link: LinkSettings
    credentials: Credentials | None  # None: no [identity] given (the companion needs one)
    log_level: str = "info"


def _path(base: Path, value: str) -> Path:
    path = Path(value).expanduser()
    return path if path.is_absolute() else base / path


def _credentials(doc: Table, base: Path, node: int) -> Credentials | None:
    """[identity] and [trust]: our key and certificate, the operators we trust."""
    if not doc.has("identity"):
        doc.known.add("trust")  # read with an identity only (the companion refuses without)
        return None
    identity = doc.table("identity")
    try:
        key = read_private_key(_path(base, identity.text("key")))
    except KeyFileError as exc:
        raise identity.fail(str(exc), "key") from None
    cert_file = _path(base, identity.text("certificate"))
    try:
        cert = Certificate.decode(cert_file.read_bytes())
    except OSError as exc:
        raise identity.fail(f"{cert_file}: {exc.strerror}", "certificate") from None
    except CertificateError as exc:
        raise identity.fail(f"{cert_file}: {exc}", "certificate") from None
    if cert.drone != key.public:
        raise identity.fail(f"{cert_file} certifies another key than identity.key")
    if cert.node != node:
        raise identity.fail(f"{cert_file} is for node {cert.node}, not node {node}")
    state = _path(base, identity.text("state_dir", "state"))
    trust = doc.table("trust")
    policy = trust.text("unknown_peers", "ignore", [p.value for p in UnknownPeers])
    operators = []
    entries = trust.tables("operator", "[[trust.operator]]")
    if not entries:
        raise trust.fail("at least one [[trust.operator]] (name, key) is needed")
    for k, entry in enumerate(entries):
        name = entry.text("name", f"operator{k}")
        text = entry.text("key")
        max_segments = entry.integer("max_segments", 256, low=1, high=MAX_SEGMENTS)
        runs = entry.integer("max_runs_per_hour", 24, low=1)
        bits = entry.integer("max_answer_bits_per_hour", 1024, low=1)
        paper_keys = entry.flag("paper_keys", False)
        try:
            public = (
                PublicKey.parse(text)
                if len(text.strip()) == 64 and not Path(text).suffix
                else read_public_key(_path(base, text))
            )
            operators.append(
                Operator(
                    name,
                    public,
                    max_segments=max_segments,
                    max_runs_per_hour=runs,
                    max_answer_bits_per_hour=bits,
                    paper_keys=paper_keys,
                )
            )
        except (KeyFileError, ValueError) as exc:
            raise entry.fail(f"({name}) {exc}") from None
    return Credentials(Identity(key, cert), TrustStore(operators, UnknownPeers(policy)), state)


def _positive(table: Table, key: str, default: float, zero: bool = False) -> float:
    return table.number(key, default, low=0.0, above=not zero)


def _merged(path: str | Path | None, overrides: dict[str, Any] | None) -> dict[str, Any]:
    """The TOML file (optional) with ``overrides`` (dotted keys, from flags) applied."""
    raw: dict[str, Any] = load_toml(path, ConfigError) if path is not None else {}
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        table = raw
        *parents, key = dotted.split(".")
        for parent in parents:
            table = table.setdefault(parent, {})
        table[key] = value
    return raw


def _link(doc: Table) -> LinkSettings:
    link = doc.table("link")
    transport = link.text("transport", LINK.transport, ("udp", "serial"))
    profile_name = link.text("profile", LINK.profile, PROFILE_NAMES)
    host, _, port = link.text("hub", "{}:{}".format(*LINK.hub)).rpartition(":")
    if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise link.fail("expected HOST:PORT with a port 1..65535", "hub")
    return LinkSettings(
        transport,
        profile_name,
        (host, int(port)),
        link.text("serial", LINK.serial),
        link.integer("baudrate", LINK.baudrate, low=1),
    )


def _offset(doc: Table) -> OffsetSettings:
    offset = doc.table("offset")
    offset_m = offset.number("offset_m", BASE.offset.offset_m, low=0.0, above=True)
    direction = offset.text("direction", BASE.offset.direction, ("up", "down"))
    max_altitude_m = offset.number(
        "max_altitude_m", BASE.offset.max_altitude_m, low=0.0, above=True
    )
    levels = offset.integer("max_levels", BASE.offset.max_levels or 0, low=0, high=100)
    try:
        return OffsetSettings(
            offset_m=offset_m,
            direction=direction,
            max_altitude_m=max_altitude_m,
            max_levels=levels or None,
        )
    except ValueError as exc:
        raise offset.fail(str(exc)) from None


def _separation(doc: Table) -> SeparationSettings:
    separation = doc.table("separation")
    return SeparationSettings(
        _positive(separation, "horizontal_m", BASE.separation.horizontal_m, zero=True),
        _positive(separation, "vertical_m", BASE.separation.vertical_m, zero=True),
        Tolerance(
            _positive(separation, "altitude_error_m", TOLERANCE.altitude_m, zero=True),
            _positive(separation, "late_s", TOLERANCE.late_s, zero=True),
            _positive(separation, "early_s", TOLERANCE.early_s, zero=True),
            _positive(separation, "time_tolerance_rate", TOLERANCE.rate, zero=True),
            _positive(separation, "ground_wait_s", 1.0)
            if "ground_wait_s" in separation.doc
            else math.inf,
        ),
    )


def _companion(doc: Table) -> functools.partial[CompanionSettings]:
    """Every setting but the node id (checked last: unknown keys are named first)."""
    limits = doc.table("limits")
    failsafe = doc.table("failsafe")
    offset = _offset(doc)
    suites = {s.label: s for s in Suite}
    suite = doc.text("suite", BASE.suite.label, list(suites))
    ot_security = doc.integer("ot_security", BASE.ot_security)
    if ot_security not in SECURITY_LEVELS:
        raise doc.fail(f"one of {', '.join(map(str, SECURITY_LEVELS))}", "ot_security")
    action = failsafe.text("action", BASE.failsafe.action.value, [a.value for a in Action])
    autopilot_url = doc.text("autopilot", DEFAULT_AUTOPILOT)
    try:
        check_url(autopilot_url)  # before the link or MAVSDK starts
    except ValueError as exc:
        raise doc.fail(str(exc), "autopilot") from None

    def count(key: str, default: int) -> int:
        return limits.integer(key, default, low=1)

    def positive(key: str, default: float, zero: bool = False) -> float:
        return _positive(limits, key, default, zero)

    return functools.partial(
        CompanionSettings,
        autopilot_url=autopilot_url,
        autopilot_connect_s=_positive(doc, "autopilot_connect_s", BASE.autopilot_connect_s),
        ardupilot=doc.flag("ardupilot", BASE.ardupilot),
        suite=suites[suite],
        ot_security=ot_security,
        offset=offset,
        beacon_interval_s=positive("beacon_interval_s", BASE.beacon_interval_s),
        initiation_range_m=positive("initiation_range_m", BASE.initiation_range_m),
        grid_radius_m=positive("grid_radius_m", BASE.grid_radius_m),
        max_box_radius_m=positive("max_box_radius_m", BASE.max_box_radius_m),
        max_peer_range_m=positive("max_peer_range_m", BASE.max_peer_range_m),
        min_grid_resolution_mm=count("min_grid_resolution_mm", BASE.min_grid_resolution_mm),
        max_runs_per_peer=count("max_runs_per_peer", BASE.max_runs_per_peer),
        max_runs_total=count("max_runs_total", BASE.max_runs_total),
        max_answer_bits_per_peer=count("max_answer_bits_per_peer", BASE.max_answer_bits_per_peer),
        max_clock_skew_s=positive("max_clock_skew_s", BASE.max_clock_skew_s),
        run_timeout_s=positive("run_timeout_s", BASE.run_timeout_s or math.inf),
        lookahead_s=positive("lookahead_s", BASE.lookahead_s, zero=True),
        failsafe=FailsafeSettings(
            Action(action), _positive(failsafe, "margin_s", BASE.failsafe.margin_s)
        ),
        separation=_separation(doc),
    )


def load_config(path: str | Path | None, overrides: dict[str, Any] | None = None) -> Config:
    """Read the TOML file (optional) and apply ``overrides`` (dotted keys, from flags); every
    key is checked (:mod:`companion.app.tables`), unknown ones included."""
    base = Path(path).parent if path is not None else Path.cwd()
    doc = Table(
        _merged(path, overrides), str(path) if path is not None else "settings", ConfigError
    )
    node = doc.optional_integer("node", low=1, high=0xFFFE)
    link = _link(doc)
    level = doc.text("log_level", "info", ("debug", "info", "warning", "error"))
    companion = _companion(doc)
    if node is None:  # unknown keys first: a misspelt "nod" says so
        doc.known |= {"identity", "trust"}
        doc.finish()
        raise doc.fail("a node id 1..65534 is required (node = N, or --node)", "node")
    credentials = _credentials(doc, base, node)
    doc.finish()
    return Config(companion(node=node), link, credentials, level)
