"""Command line of the flight companion (``drone-deconflict`` or ``python -m companion``):
run, keys, replay, fleet, compare, bench-link, radio-demo, link-hub, mock-autopilot, mission show.
Errors are one line and exit 2 (:mod:`protocol.tools.cli`)."""

from __future__ import annotations

import argparse
import asyncio
import difflib
import sys
from typing import Any, TypeAlias

from companion.cli import commands
from companion.cli import keys as keys_cli
from companion.errors import CompanionError
from companion.radio.airtime import PHY_MAX_FRAME, PROFILES
from protocol.tools import cli

DESCRIPTION = (
    "The flight companion of private drone deconfliction: it reads the mission through "
    "MAVSDK, compares paths with peer drones over the radio without showing them, and flies "
    "conflicting segments higher."
)
MAX_INSTANCE = 253  # system id I + 1 <= 254 (255 is the ground station)


def _profile(text: str) -> str:
    """A link profile name we know."""
    if text not in PROFILES:
        raise argparse.ArgumentTypeError(
            f"unknown link profile {text!r}; known: {', '.join(PROFILES)}"
        )
    return text


def _profiles(text: str) -> tuple[str, ...]:
    """Comma-separated link profile names, each one we know."""
    return tuple(_profile(p.strip()) for p in text.split(","))


def _autopilot_url(text: str) -> str:
    """A MAVSDK connection URL (:func:`companion.mission.autopilot.check_url`)."""
    from companion.mission.autopilot import check_url

    try:
        return check_url(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _mavlink_message(text: str) -> str:
    """The name of a MAVLink message of the common dialect (what the mock may ignore)."""
    from pymavlink.dialects.v20 import common as mavlink

    names = {m.msgname for m in mavlink.mavlink_map.values()}
    name = text.strip().upper()
    if name not in names:
        close = difflib.get_close_matches(name, names, 1)
        hint = f"did you mean {close[0]}?" if close else "e.g. MISSION_COUNT"
        raise argparse.ArgumentTypeError(f"{text!r} is not a MAVLink message ({hint})")
    return name


def _log_flags(parser: argparse.ArgumentParser, level_help: str) -> None:
    """--log-level and --log-json (:mod:`companion.logs`)."""
    parser.add_argument(
        "--log-level", choices=["debug", "info", "warning", "error"], help=level_help
    )
    parser.add_argument(
        "--log-json", type=cli.output_file(), help="append every log record as JSON lines"
    )


Subparsers: TypeAlias = "argparse._SubParsersAction[Any]"  # the subcommands


def _add_hub(sub: Subparsers) -> None:
    hub = sub.add_parser("link-hub", help="a simulated radio channel shared over UDP")
    hub.add_argument("--host", type=cli.host, default="127.0.0.1", help="address to listen on")
    hub.add_argument(
        "--port", type=cli.listen_port, default=14600, help="UDP port to listen on (0: any)"
    )
    hub.add_argument("--loss", type=cli.probability, default=0.0, help="frame loss probability")
    hub.add_argument("--corrupt", type=cli.probability, default=0.0, help="corruption probability")
    hub.add_argument("--duplicate", type=cli.probability, default=0.0, help="duplication rate")
    hub.add_argument("--reorder", type=cli.probability, default=0.0, help="reordering probability")
    hub.add_argument("--latency", type=cli.number(0, 60), default=0.002, help="seconds")
    hub.add_argument("--seed", type=cli.seed, default=None, help="channel seed (default: random)")
    hub.add_argument(
        "--time-scale", type=cli.number(0, 10_000, above=True), default=1.0, help="speed-up"
    )
    hub.add_argument("--no-collisions", action="store_true", help="overlapping frames both pass")
    hub.set_defaults(func=lambda a: asyncio.run(commands.hub(a)))


def _add_mock(sub: Subparsers) -> None:
    mock = sub.add_parser("mock-autopilot", help="a MAVLink autopilot for tests and replays")
    mock.add_argument(
        "--mission", type=cli.existing_file, help=".plan or QGC WPL 110 file to start with"
    )
    mock.add_argument(
        "--instance",
        type=cli.integer(0, MAX_INSTANCE),
        default=0,
        help="binds UDP 14580+I, sends to 14540+I, system id I+1",
    )
    mock.add_argument("--ardupilot", action="store_true", help="ArduPilot personality")
    home_help = "home %s (default: the mission file's home, else %s)"
    bounds = {"lat": cli.number(-90, 90), "lon": cli.number(-180, 180)}
    bounds["alt"] = cli.number(-500, 9000)
    for key, value in zip(("lat", "lon", "alt"), commands.DEFAULT_HOME, strict=True):
        mock.add_argument(
            f"--home-{key}", type=bounds[key], default=None, help=home_help % (key, value)
        )
    mock.add_argument("--speed", type=cli.number(0, 100, above=True), default=10.0, help="m/s")
    mock.add_argument(
        "--time-scale", type=cli.number(0, 10_000, above=True), default=1.0, help="speed-up"
    )
    mock.add_argument(
        "--drop-every",
        type=cli.integer(1),
        default=None,
        metavar="K",
        help="drop every K-th mission-protocol reply (default: none dropped)",
    )
    mock.add_argument(
        "--latency", type=cli.number(0, 60), default=0.0, help="seconds added to replies"
    )
    mock.add_argument(
        "--ignore",
        action="append",
        type=_mavlink_message,
        metavar="MESSAGE",
        help="a MAVLink message to ignore, e.g. MISSION_COUNT; repeatable (default: none)",
    )
    mock.add_argument(
        "--reject-upload",
        type=cli.integer(1, 255),
        default=None,
        help="answer every upload with this MAV_MISSION_RESULT (default: accept)",
    )
    mock.add_argument(
        "--vanish-after",
        type=cli.number(0, above=True),
        default=None,
        help="stop answering after this many seconds (default: never)",
    )
    mock.add_argument(
        "--trajectory",
        type=cli.output_file(".csv"),
        help="write the flown trajectory (CSV) on exit",
    )
    mock.set_defaults(func=lambda a: asyncio.run(commands.mock(a)))


def _add_mission(sub: Subparsers) -> None:
    mission = sub.add_parser("mission", help="mission files")
    mission_sub = mission.add_subparsers(dest="action", required=True, metavar="ACTION")
    show = mission_sub.add_parser("show", help="print a mission and its segments")
    show.add_argument("file", type=cli.existing_file, help=".plan or QGC WPL 110 file")
    show.add_argument("--ardupilot", action="store_true", help="item 0 is home")
    show.set_defaults(func=commands.mission_show)


def _add_compare(sub: Subparsers) -> None:
    compare = sub.add_parser("compare", help="the encrypted path comparison over the radio link")
    compare.add_argument(
        "alice",
        type=cli.existing_file,
        help="Alice's paths: paper format (x,y)(x,y)..., or a mission file (.plan, QGC WPL): "
        "the path it flies",
    )
    compare.add_argument("bob", type=cli.existing_file, help="Bob's paths, same format as Alice's")
    compare.add_argument(
        "--link",
        metavar="PROFILE",
        required=True,
        type=_profile,
        help=f"link profile: {', '.join(PROFILES)}",
    )
    compare.add_argument(
        "--suite",
        choices=["compact", "paper"],
        default="compact",
        help="compact (OT extension: SoftSpokenOT, OT products, millionaires, GMW) or paper "
        "(Paillier + DGK)",
    )
    compare.add_argument(
        "--range",
        type=cli.integer(1, 1 << 28),
        default=None,
        help="public grid range R (default: the files' extent)",
    )
    compare.add_argument("--loss", type=cli.probability, default=0.0, help="frame loss probability")
    compare.add_argument(
        "--corrupt", type=cli.probability, default=0.0, help="corruption probability"
    )
    compare.add_argument(
        "--seed", type=cli.seed, default=None, help="channel seed (default: random)"
    )
    compare.add_argument(
        "--mtu",
        type=cli.integer(32, PHY_MAX_FRAME),
        default=None,
        help="radio frame size in bytes (default: the profile's)",
    )
    compare.add_argument("--json", action="store_true", help="machine-readable output")
    compare.set_defaults(func=commands.compare)


def _add_bench(sub: Subparsers) -> None:
    bench = sub.add_parser(
        "bench-link", help="30 single-segment pairs and an 8x8 run over each profile"
    )
    bench.add_argument(
        "--data",
        type=cli.existing_dir,
        default=None,
        help="directory with the paper's benchmark files, whose 30 pairs are run (default: 30 "
        "random pairs in +-99; the project does not carry the paper's files, e.g. "
        "../shared/anchor-data)",
    )
    bench.add_argument(
        "--profiles", type=_profiles, help="comma-separated link profiles (default: all)"
    )
    bench.add_argument(
        "--suite", choices=["compact", "paper"], default="compact", help="cryptographic suite"
    )
    bench.add_argument(
        "--range", type=cli.integer(1, 1 << 28), default=99, help="coordinate range of the 8x8 run"
    )
    bench.add_argument(
        "--pairs",
        type=cli.integer(1, 30),
        default=None,
        help="run only the first N of the 30 pairs (a quick look; default: all)",
    )
    bench.add_argument("--json", action="store_true", help="machine-readable output")
    bench.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    bench.set_defaults(func=commands.bench_link)


def _add_demo(sub: Subparsers) -> None:
    demo = sub.add_parser("radio-demo", help="the demo's comparison over simulated LoRa profiles")
    demo.set_defaults(func=lambda a: commands.radio_demo())


def _add_replay(sub: Subparsers) -> None:
    replay = sub.add_parser("replay", help="fly a scenario: mock autopilots, MAVSDK, companions")
    replay.add_argument(
        "scenario", type=cli.existing_file, help="scenario TOML (see sitl_configs/scenarios/)"
    )
    replay.add_argument("--json", action="store_true", help="print the report as JSON")
    replay.add_argument(
        "--out", type=cli.output_file(".json"), help="also write the JSON report to this file"
    )
    replay.add_argument(
        "--plot",
        type=cli.output_file(".png", ".pdf", ".svg"),
        help="write the encounter's plot (tracks, separation, altitude): PNG, PDF or SVG",
    )
    replay.add_argument(
        "--export",
        type=cli.output_dir,
        metavar="DIR",
        help="write flown tracks (CSV), the encounter as KML (Google Earth) and GeoJSON",
    )
    replay.add_argument(
        "--px4",
        metavar="DIR",
        help="fly PX4 SITL (SIH) vehicles from the build in DIR (bin/px4, etc/) instead of mocks",
    )
    replay.add_argument(
        "--virtual",
        action="store_true",
        help="fly in virtual time: mock vehicles in this process, no MAVLink or MAVSDK (minutes "
        "of flight in seconds, the same on a busy machine; MAVLink faults need the default)",
    )
    replay.add_argument(
        "--px4-speed",
        type=cli.number(0, 100, above=True),
        default=None,
        help="largest SIH speed factor, the replay's time scale with --px4 (default: 5, at "
        "which two vehicles, their companions and the protocol keep up on 2 cores)",
    )
    _log_flags(replay, "companions' log on stderr (default: warning)")
    replay.set_defaults(func=commands.replay)


def _add_fleet(sub: Subparsers) -> None:
    fleet = sub.add_parser(
        "fleet", help="a city's hour of drone traffic in virtual time (fleet simulation)"
    )
    fleet.add_argument(
        "--drones", type=cli.integer(2, 250), default=100, help="default: %(default)s"
    )
    fleet.add_argument(
        "--hours", type=cli.number(0, 8, above=True), default=1.0, help="default: %(default)s"
    )
    fleet.add_argument(
        "--area-km",
        type=cli.number(0, 100, above=True),
        default=6.0,
        help="side of the square the drones fly over, km (default: %(default)s)",
    )
    fleet.add_argument(
        "--range-km",
        type=cli.number(0, 100, above=True),
        default=3.0,
        help="radio range, km (default: %(default)s)",
    )
    fleet.add_argument(
        "--profile", type=_profile, default="us915-sf7", help="link profile (default: %(default)s)"
    )
    fleet.add_argument(
        "--loss", type=cli.number(0, 0.9), default=0.1, help="frame loss (default: %(default)s)"
    )
    fleet.add_argument(
        "--seed",
        type=cli.integer(0, 2**31),
        default=1,
        help="traffic and radio (default: %(default)s)",
    )
    fleet.add_argument("--json", action="store_true", help="print the summary as JSON")
    fleet.add_argument("--out", help="also write the whole replay report (JSON) to this file")
    fleet.add_argument("--progress", action="store_true", help="tell the story on stderr")
    fleet.set_defaults(func=commands.fleet)


def _add_run(sub: Subparsers) -> None:
    run = sub.add_parser("run", help="the companion process beside one autopilot")
    run.add_argument(
        "--config", type=cli.existing_file, help="TOML settings, [identity] and [trust] included"
    )
    # Defaults come from the config file, else from companion/app/config.py (the help names
    # both; tests/test_cli_errors.py checks they agree).
    given = "default: the config's %s, else %s"
    run.add_argument(
        "--node",
        type=cli.integer(1, 0xFFFE),
        help="node id on the radio (default: the config's node; one is required)",
    )
    run.add_argument(
        "--autopilot",
        type=_autopilot_url,
        help="MAVSDK URL: udpin://IP:PORT, udpout://HOST:PORT, tcpin/tcpout://..., "
        f"serial:///dev/DEVICE:BAUD ({given % ('autopilot', 'udpin://0.0.0.0:14540')})",
    )
    run.add_argument(
        "--transport",
        choices=["udp", "serial"],
        help=f"link transport ({given % ('link.transport', 'udp')})",
    )
    run.add_argument(
        "--profile",
        type=_profile,
        help=f"link profile: {', '.join(PROFILES)} ({given % ('link.profile', 'us915-sf7')})",
    )
    run.add_argument(
        "--hub",
        help=f"link hub HOST:PORT, udp transport ({given % ('link.hub', '127.0.0.1:14600')})",
    )
    run.add_argument(
        "--serial",
        help=f"serial device of the LoRa modem ({given % ('link.serial', '/dev/ttyUSB0')})",
    )
    run.add_argument(
        "--offset",
        type=cli.number(0, 500, above=True),
        help=f"altitude offset, m ({given % ('offset.offset_m', '10.0')})",
    )
    run.add_argument(
        "--separation",
        type=cli.number(0, 10_000),
        help=f"horizontal separation, m ({given % ('separation.horizontal_m', '15.0')})",
    )
    run.add_argument(
        "--vertical-separation",
        type=cli.number(0, 10_000),
        help=f"vertical separation, m ({given % ('separation.vertical_m', '10.0')})",
    )
    run.add_argument(
        "--max-altitude",
        type=cli.number(0, 10_000, above=True),
        help=f"metres above home ({given % ('offset.max_altitude_m', '120.0')})",
    )
    _log_flags(run, "log level (default: the config's, else info)")
    run.set_defaults(func=commands.run_command)


def _parser() -> argparse.ArgumentParser:
    """The command line: one function per subcommand."""
    parser = cli.Parser(prog="drone-deconflict", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_hub(sub)
    _add_mock(sub)
    _add_mission(sub)
    _add_compare(sub)
    _add_bench(sub)
    _add_demo(sub)
    _add_replay(sub)
    _add_fleet(sub)
    _add_run(sub)
    keys_cli.add_parser(sub)
    cli.add_common(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    return cli.run(args.func, args, (CompanionError,))


if __name__ == "__main__":
    sys.exit(main())
