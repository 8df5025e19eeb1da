"""Settings of ``python -m companion run``: a TOML file, every key also a command-line flag.

::

    node = 1
    autopilot = "udpin://0.0.0.0:14540"   # MAVSDK URL; PX4 SITL instance i: 14540 + i
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
    [limits]
    max_runs_per_peer = 8                 # runs one certified drone may ask of us per hour
    max_runs_total = 64                   # runs all drones together may ask of us per hour
    max_clock_skew_s = 30.0               # beacons and requests further off: refused
    run_timeout_s = 900.0
    beacon_interval_s = 10.0
    initiation_range_m = 5000.0
    lookahead_s = 60.0                    # compare at least the next 60 s of flight first
    grid_radius_m = 500.0                 # smallest comparison box (doubled to hold the path)
    [failsafe]
    action = "climb"                      # "climb", "hold" or "off"
    margin_s = 10.0
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from protocol.ot.setup import DEFAULT_SECURITY, SECURITY_LEVELS
from protocol.wire import Suite

from .auth.certificate import Certificate, CertificateError
from .auth.keys import KeyFileError, PublicKey, read_private_key, read_public_key
from .auth.session import Identity
from .auth.trust import Operator, TrustStore, UnknownPeers
from .failsafe import Action, FailsafeSettings
from .link.airtime import profile as link_profile
from .planner import OffsetSettings
from .runtime import CompanionSettings, Credentials


class ConfigError(ValueError):
    """The configuration is invalid; says which key."""


@dataclass(frozen=True)
class LinkSettings:
    transport: str = "udp"
    profile: str = "us915-sf7"
    hub: tuple[str, int] = ("127.0.0.1", 14600)
    serial: str = "/dev/ttyUSB0"
    baudrate: int = 115200


@dataclass(frozen=True)
class Config:
    companion: CompanionSettings
    link: LinkSettings
    credentials: Credentials | None  # None: no [identity] given (the companion needs one)
    log_level: str = "info"


def _path(base: Path, value: str) -> Path:
    path = Path(value).expanduser()
    return path if path.is_absolute() else base / path


def _credentials(doc: dict[str, Any], base: Path, node: int) -> Credentials | None:
    """[identity] and [trust]: our key and certificate, the operators we trust."""
    identity = doc.get("identity")
    if identity is None:
        return None
    try:
        key = read_private_key(_path(base, _get(identity, "key", str, None)))
        cert_file = _path(base, _get(identity, "certificate", str, None))
        try:
            cert = Certificate.decode(cert_file.read_bytes())
        except OSError as exc:
            raise ConfigError(f"identity.certificate: {cert_file}: {exc.strerror}") from None
        except CertificateError as exc:
            raise ConfigError(f"identity.certificate: {cert_file}: {exc}") from None
        if cert.drone != key.public:
            raise ConfigError(f"identity: {cert_file} certifies another key than identity.key")
        if cert.node != node:
            raise ConfigError(f"identity: {cert_file} is for node {cert.node}, not node {node}")
        state = _path(base, _get(identity, "state_dir", str, "state"))
    except KeyFileError as exc:
        raise ConfigError(f"identity.key: {exc}") from None
    trust = doc.get("trust", {})
    policy = _get(trust, "unknown_peers", str, "ignore")
    policies = {p.value: p for p in UnknownPeers}
    if policy not in policies:
        raise ConfigError(f"trust.unknown_peers: one of {', '.join(policies)}")
    operators = []
    entries = trust.get("operator", [])
    if not isinstance(entries, list) or not entries:
        raise ConfigError("trust.operator: at least one [[trust.operator]] (name, key)")
    for k, entry in enumerate(entries):
        where = f"trust.operator[{k}]"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where}: a table")
        name = _get(entry, "name", str, f"operator{k}")
        text = _get(entry, "key", str, None)
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
                    _get(entry, "max_segments", int, 256),
                    _get(entry, "max_runs_per_hour", int, 24),
                )
            )
        except (KeyFileError, ValueError) as exc:
            raise ConfigError(f"{where} ({name}): {exc}") from None
    return Credentials(Identity(key, cert), TrustStore(operators, policies[policy]), state)


def _get(table: dict[str, Any], key: str, kind: type, default: Any) -> Any:
    value = table.get(key, default)
    if value is None:
        raise ConfigError(f"{key}: required")
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise ConfigError(f"{key}: expected {kind.__name__}, got {value!r}")
    return value


def load_config(path: str | Path | None, overrides: dict[str, Any] | None = None) -> Config:
    """Read the TOML file (optional) and apply ``overrides`` (dotted keys, from flags)."""
    doc: dict[str, Any] = {}
    base = Path(path).parent if path is not None else Path.cwd()
    if path is not None:
        try:
            doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path}: {exc}") from None
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        table = doc
        *parents, key = dotted.split(".")
        for parent in parents:
            table = table.setdefault(parent, {})
        table[key] = value
    link = doc.get("link", {})
    offset = doc.get("offset", {})
    limits = doc.get("limits", {})
    failsafe = doc.get("failsafe", {})
    node = _get(doc, "node", int, None) if "node" in doc else None
    if node is None or not 1 <= node < 0xFFFF:
        raise ConfigError("node: a node id 1..65534 is required")
    transport = _get(link, "transport", str, "udp")
    if transport not in ("udp", "serial"):
        raise ConfigError("link.transport: 'udp' or 'serial'")
    profile_name = _get(link, "profile", str, "us915-sf7")
    try:
        link_profile(profile_name)
    except ValueError as exc:
        raise ConfigError(f"link.profile: {exc}") from None
    host, _, port = _get(link, "hub", str, "127.0.0.1:14600").rpartition(":")
    if not host or not port.isdigit():
        raise ConfigError("link.hub: HOST:PORT")
    level = _get(doc, "log_level", str, "info").lower()
    if level not in ("debug", "info", "warning", "error"):
        raise ConfigError("log_level: debug, info, warning or error")
    try:
        offset_settings = OffsetSettings(
            offset_m=_get(offset, "offset_m", float, 10.0),
            direction=_get(offset, "direction", str, "up"),
            max_altitude_m=_get(offset, "max_altitude_m", float, 120.0),
        )
    except ValueError as exc:
        raise ConfigError(f"offset: {exc}") from None
    suites = {s.label: s for s in Suite}
    suite = _get(doc, "suite", str, "compact")
    if suite not in suites:
        raise ConfigError(f"suite: one of {', '.join(suites)}")
    ot_security = _get(doc, "ot_security", int, DEFAULT_SECURITY)
    if ot_security not in SECURITY_LEVELS:
        raise ConfigError(f"ot_security: one of {', '.join(map(str, SECURITY_LEVELS))}")
    actions = {a.value: a for a in Action}
    action = _get(failsafe, "action", str, "climb")
    if action not in actions:
        raise ConfigError(f"failsafe.action: one of {', '.join(actions)}")
    numbers = {
        "max_clock_skew_s": _get(limits, "max_clock_skew_s", float, 30.0),
        "beacon_interval_s": _get(limits, "beacon_interval_s", float, 10.0),
        "initiation_range_m": _get(limits, "initiation_range_m", float, 5000.0),
        "run_timeout_s": _get(limits, "run_timeout_s", float, 900.0),
        "lookahead_s": _get(limits, "lookahead_s", float, 60.0),
        "grid_radius_m": _get(limits, "grid_radius_m", float, 500.0),
        "margin_s": _get(failsafe, "margin_s", float, 10.0),
    }
    for key, value in numbers.items():
        if value < 0 or (key != "lookahead_s" and value == 0):
            raise ConfigError(f"{key}: must be positive")
    for key in ("max_runs_per_peer", "max_runs_total"):
        if _get(limits, key, int, 1) < 1:
            raise ConfigError(f"limits.{key}: at least 1")
    companion = CompanionSettings(
        node=node,
        autopilot_url=_get(doc, "autopilot", str, "udpin://0.0.0.0:14540"),
        ardupilot=_get(doc, "ardupilot", bool, False),
        suite=suites[suite],
        ot_security=ot_security,
        offset=offset_settings,
        beacon_interval_s=numbers["beacon_interval_s"],
        initiation_range_m=numbers["initiation_range_m"],
        grid_radius_m=numbers["grid_radius_m"],
        max_runs_per_peer=_get(limits, "max_runs_per_peer", int, 8),
        max_runs_total=_get(limits, "max_runs_total", int, 64),
        max_clock_skew_s=numbers["max_clock_skew_s"],
        run_timeout_s=numbers["run_timeout_s"],
        lookahead_s=numbers["lookahead_s"],
        failsafe=FailsafeSettings(actions[action], numbers["margin_s"]),
    )
    return Config(
        companion,
        LinkSettings(
            transport,
            profile_name,
            (host, int(port)),
            _get(link, "serial", str, "/dev/ttyUSB0"),
            _get(link, "baudrate", int, 115200),
        ),
        _credentials(doc, base, node),
        level,
    )
