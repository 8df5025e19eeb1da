"""Command line of the flight companion (``drone-deconflict`` or ``python -m companion``):
run, keys, replay, compare, bench-link, radio-demo, link-hub, mock-autopilot, mission show.
Errors are one line and exit 2 (:mod:`protocol.tools.cli`)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import signal
import sys
from pathlib import Path

from protocol.tools import cli

from . import keys_cli, logs
from .link import Channel, Clock, Impairments
from .link.airtime import PHY_MAX_FRAME, PROFILES
from .link.udp import UdpHub

DESCRIPTION = (
    "The flight companion of private drone deconfliction: it reads the mission through "
    "MAVSDK, compares paths with peer drones over the radio without showing them, and flies "
    "conflicting segments higher."
)
MAX_INSTANCE = 253  # system id I + 1 <= 254 (255 is the ground station)

DEFAULT_HOME = (47.397742, 8.545594, 488.0)  # PX4 SITL's default home


def _stop_on_signals() -> asyncio.Event:
    """An event set by SIGINT/SIGTERM (install before announcing readiness)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    return stop


async def _hub(args: argparse.Namespace) -> int:
    impairments = Impairments(
        loss=args.loss,
        corrupt=args.corrupt,
        duplicate=args.duplicate,
        reorder=args.reorder,
        latency_s=args.latency,
    )
    channel = Channel(impairments, args.seed, collisions=not args.no_collisions)
    hub = await UdpHub.serve(channel, args.host, args.port, Clock(args.time_scale))
    host, port = hub.address
    stop = _stop_on_signals()
    print(f"link hub on udp://{host}:{port} ({impairments})", flush=True)
    await stop.wait()
    hub.close()
    print(f"hub stopped: {channel.stats}", flush=True)
    return 0


async def _mock(args: argparse.Namespace) -> int:
    from .missionfile import read_mission_file
    from .sim.mock_autopilot import Faults, FlightModel, MockAutopilot

    given = (args.home_lat, args.home_lon, args.home_alt)
    home = tuple(DEFAULT_HOME[i] if v is None else v for i, v in enumerate(given))
    mission = []
    if args.mission:
        plan = read_mission_file(args.mission)
        if plan.home is not None and all(v is None for v in given):
            home = plan.home  # the file's home, unless the command line gives one
        mission = plan.for_autopilot(ardupilot=args.ardupilot)
        if args.ardupilot:  # item 0 is the vehicle's home
            lat, lon = round(home[0] * 1e7), round(home[1] * 1e7)
            mission[0] = mission[0].replace(x=lat, y=lon, z=home[2])
    faults = Faults(
        drop_every=args.drop_every,
        latency_s=args.latency,
        ignore=frozenset(args.ignore or ()),
        reject_upload=args.reject_upload,
        vanish_after_s=args.vanish_after,
    )
    flight = FlightModel(cruise_m_s=args.speed, time_scale=args.time_scale)
    mock = MockAutopilot(
        args.instance,
        mission=mission,
        ardupilot=args.ardupilot,
        faults=faults,
        flight=flight,
        home=(home[0], home[1], home[2]),
    )
    async with mock:
        stop = _stop_on_signals()
        kind = "ArduPilot" if args.ardupilot else "PX4"
        print(
            f"mock {kind} autopilot, system {mock.sysid}: listening on udp {mock.host}:"
            f"{mock.bind_port}, sending to {mock.send_port} ({len(mission)} mission items)",
            flush=True,
        )
        await stop.wait()
    if args.trajectory:
        from .sim.export import track_csv

        cli.write_atomic(args.trajectory, track_csv(mock.trajectory))
    return 0


def _mission_show(args: argparse.Namespace) -> int:
    from pymavlink.dialects.v20 import common as mavlink

    from .flightpath import flight_path
    from .mission import MissionError
    from .missionfile import read_mission_file

    plan = read_mission_file(args.file)
    try:
        items = plan.for_autopilot(ardupilot=args.ardupilot)
        path = flight_path(items, plan.home_degE7, ardupilot=args.ardupilot)
    except MissionError as exc:
        raise MissionError(f"{args.file}: {exc}") from None
    commands = mavlink.enums["MAV_CMD"]

    def name(command: int) -> str:
        """MAVLink's own name of a command (NAV_WAYPOINT, DO_CHANGE_SPEED, ...)."""
        entry = commands.get(command)
        return entry.name.removeprefix("MAV_CMD_") if entry is not None else str(command)

    def where(k: int) -> str:
        v = path.vertices[k]
        items_ = "/".join(str(i) for i in v.items) or "-"
        return f"{v.kind.value} (item {items_})"

    on_path = {i for v in path.vertices for i in v.items}
    movable = {i for v in path.vertices for i in v.moves}
    if plan.home is not None:
        print(f"home: {plan.home[0]:.7f}, {plan.home[1]:.7f}, {plan.home[2]:.1f} m AMSL")
    print("| seq | command | frame | lat | lon | alt m | on path | edits move it |")
    print("|---:|---|---:|---:|---:|---:|---|---|")
    for it in items:
        print(
            f"| {it.seq} | {name(it.command)} | {it.frame} | {it.x / 1e7:.7f} | {it.y / 1e7:.7f} "
            f"| {it.z:.1f} | {'yes' if it.seq in on_path else ''} "
            f"| {'yes' if it.seq in movable else ''} |"
        )
    print(f"\nSegments of the flown path (what the protocol compares): {path.segments}")
    for k in range(path.segments):
        print(f"  segment {k}: {where(k)} -> {where(k + 1)}")
    return 0


async def _run(args: argparse.Namespace) -> int:
    import logging

    from .autopilot import Autopilot
    from .autopilots import personality
    from .config import load_config
    from .link import LinkEndpoint, profile
    from .link.medium import Transport
    from .runtime import Companion

    config = load_config(
        args.config,
        {
            "node": args.node,
            "autopilot": args.autopilot,
            "log_level": args.log_level,
            "link.transport": args.transport,
            "link.profile": args.profile,
            "link.hub": args.hub,
            "link.serial": args.serial,
            "offset.offset_m": args.offset,
            "offset.max_altitude_m": args.max_altitude,
        },
    )
    logs.setup(config.log_level, args.log_json, mavsdk=True)
    log = logging.getLogger("companion")
    settings, link = config.companion, config.link
    if config.credentials is None:
        raise cli.InputError(
            "the companion needs an identity: [identity] key, certificate and [[trust.operator]] "
            "in --config (python -m companion keys init|certify)"
        )
    transport: Transport
    if link.transport == "serial":
        from .link.serial_port import SerialTransport

        transport = SerialTransport.open(link.serial, link.baudrate)
    else:
        from .link.udp import UdpTransport

        transport = await UdpTransport.connect(settings.node, link.hub)
    endpoint = LinkEndpoint(settings.node, transport, profile(link.profile))
    log.info("node %d: connecting to the autopilot at %s", settings.node, settings.autopilot_url)
    autopilot = await Autopilot.connect(
        settings.autopilot_url, personality=personality(settings.ardupilot)
    )
    companion = Companion(settings, endpoint, autopilot, config.credentials)
    stop = _stop_on_signals()
    try:
        await companion.start()
        log.info(
            "node %d: running (link %s over %s); SIGINT/SIGTERM to stop",
            settings.node,
            link.profile,
            link.transport,
        )
        await stop.wait()
        log.info("node %d: stopping", settings.node)
    finally:
        await companion.stop()
        await autopilot.close()
    return 0


def _replay(args: argparse.Namespace) -> int:
    from .sim.export import export
    from .sim.plot import plot_report
    from .sim.px4 import Px4Error, find_build
    from .sim.replay import PX4_SPEED_MAX, run_replay
    from .sim.report import format_report
    from .sim.scenario import load_scenario

    level = args.log_level or ("info" if args.log_json else "warning")
    logs.setup(level, args.log_json, stderr_level=args.log_level or "warning", mavsdk=True)
    scenario = load_scenario(args.scenario)  # all checked before anything starts
    try:
        build = find_build(args.px4) if args.px4 else None
    except Px4Error as exc:
        raise cli.InputError(f"PX4 SITL: {exc}") from None
    replay = asyncio.run(
        run_replay(
            scenario,
            progress=not args.json,
            px4=build,
            px4_speed_max=PX4_SPEED_MAX if args.px4_speed is None else args.px4_speed,
        )
    )
    report = replay.report
    if args.out:
        cli.write_atomic(args.out, json.dumps(report, indent=2) + "\n")
    if args.plot:
        plot_report(replay, args.plot)
    if args.export:
        for path in export(replay, args.export):
            print(f"wrote {path}", file=sys.stderr)
    print(json.dumps(report, indent=2) if args.json else format_report(report))
    return cli.EXIT_OK if report["ok"] else cli.EXIT_NEGATIVE


def _compare(args: argparse.Namespace) -> int:
    """The protocol's comparison over the simulated radio (the radio is the companion's)."""
    from protocol.tools.compare import format_compare

    from .link import profile
    from .sim.over_link import compare_over_link

    link = profile(args.link)
    if args.mtu is not None:
        largest = link.with_mtu(PHY_MAX_FRAME).max_frame
        if args.mtu > largest:
            raise cli.InputError(
                f"--mtu {args.mtu}: {link.name} carries at most {largest} bytes per frame"
                + (f" ({link.dwell_s * 1000:.0f} ms dwell time)" if link.dwell_s else "")
            )
        link = link.with_mtu(args.mtu)
    result = compare_over_link(
        args.alice,
        args.bob,
        args.suite,
        link,
        Impairments(loss=args.loss, corrupt=args.corrupt),
        args.seed,
        range_=args.range,
        progress=not args.json,
    )
    print(json.dumps(result, indent=2) if args.json else format_compare(result))
    return 0 if all(c["hits"] == c["plain_hits"] for c in result["cases"]) else 1


def _bench_link(args: argparse.Namespace) -> int:
    from protocol.tools.bench_paths import DEFAULT_DATA

    from .sim.over_link import bench_link, format_link

    data = Path(args.data) if args.data else DEFAULT_DATA
    profiles = list(args.profiles) if args.profiles else None
    result = bench_link(
        data, profiles, suite=args.suite, range_=args.range, progress=not args.quiet
    )
    print(json.dumps(result, indent=2) if args.json else format_link(result))
    return 0


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


def _log_flags(parser: argparse.ArgumentParser, level_help: str) -> None:
    """--log-level and --log-json (:mod:`companion.logs`)."""
    parser.add_argument(
        "--log-level", choices=["debug", "info", "warning", "error"], help=level_help
    )
    parser.add_argument(
        "--log-json", type=cli.output_file(), help="append every log record as JSON lines"
    )


def _parser() -> argparse.ArgumentParser:
    parser = cli.Parser(prog="drone-deconflict", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    probability = cli.probability
    hub = sub.add_parser("link-hub", help="a simulated radio channel shared over UDP")
    hub.add_argument("--host", default="127.0.0.1", help="address to listen on")
    hub.add_argument(
        "--port", type=cli.listen_port, default=14600, help="UDP port to listen on (0: any)"
    )
    hub.add_argument("--loss", type=probability, default=0.0, help="frame loss probability")
    hub.add_argument("--corrupt", type=probability, default=0.0, help="corruption probability")
    hub.add_argument("--duplicate", type=probability, default=0.0, help="duplication rate")
    hub.add_argument("--reorder", type=probability, default=0.0, help="reordering probability")
    hub.add_argument("--latency", type=cli.number(0, 60), default=0.002, help="seconds")
    hub.add_argument("--seed", type=cli.seed, default=None, help="channel seed (random if unset)")
    hub.add_argument(
        "--time-scale", type=cli.number(0, 10_000, above=True), default=1.0, help="speed-up"
    )
    hub.add_argument("--no-collisions", action="store_true", help="overlapping frames both pass")
    hub.set_defaults(func=lambda a: asyncio.run(_hub(a)))

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
    for key, value in zip(("lat", "lon", "alt"), DEFAULT_HOME, strict=True):
        mock.add_argument(
            f"--home-{key}", type=bounds[key], default=None, help=home_help % (key, value)
        )
    mock.add_argument("--speed", type=cli.number(0, 100, above=True), default=10.0, help="m/s")
    mock.add_argument(
        "--time-scale", type=cli.number(0, 10_000, above=True), default=1.0, help="speed-up"
    )
    mock.add_argument(
        "--drop-every", type=cli.integer(0), default=0, help="drop every k-th mission reply"
    )
    mock.add_argument(
        "--latency", type=cli.number(0, 60), default=0.0, help="seconds added to replies"
    )
    mock.add_argument("--ignore", action="append", help="MAVLink message name to ignore")
    mock.add_argument(
        "--reject-upload", type=cli.integer(1, 255), default=None, help="MAV_MISSION_RESULT"
    )
    mock.add_argument(
        "--vanish-after", type=cli.number(0, above=True), default=None, help="seconds"
    )
    mock.add_argument(
        "--trajectory",
        type=cli.output_file(".csv"),
        help="write the flown trajectory (CSV) on exit",
    )
    mock.set_defaults(func=lambda a: asyncio.run(_mock(a)))

    mission = sub.add_parser("mission", help="mission files")
    mission_sub = mission.add_subparsers(dest="action", required=True, metavar="ACTION")
    show = mission_sub.add_parser("show", help="print a mission and its segments")
    show.add_argument("file", type=cli.existing_file, help=".plan or QGC WPL 110 file")
    show.add_argument("--ardupilot", action="store_true", help="item 0 is home")
    show.set_defaults(func=_mission_show)

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
        help="compact (OT + EC-ElGamal) or paper (Paillier + DGK)",
    )
    compare.add_argument(
        "--range",
        type=cli.integer(1, 1 << 28),
        default=None,
        help="public grid range R (default: the files' extent)",
    )
    compare.add_argument("--loss", type=probability, default=0.0, help="frame loss probability")
    compare.add_argument("--corrupt", type=probability, default=0.0, help="corruption probability")
    compare.add_argument(
        "--seed", type=cli.seed, default=None, help="channel seed (random if unset)"
    )
    compare.add_argument(
        "--mtu",
        type=cli.integer(32, PHY_MAX_FRAME),
        default=None,
        help="radio frame size in bytes (default: the profile's)",
    )
    compare.add_argument("--json", action="store_true", help="machine-readable output")
    compare.set_defaults(func=_compare)

    bench = sub.add_parser("bench-link", help="the paper's pairs and an 8x8 run over each profile")
    bench.add_argument("--data", help="directory with the paper's data (default: the bundled copy)")
    bench.add_argument(
        "--profiles", type=_profiles, help="comma-separated link profiles (default: all)"
    )
    bench.add_argument(
        "--suite", choices=["compact", "paper"], default="compact", help="cryptographic suite"
    )
    bench.add_argument(
        "--range", type=cli.integer(1, 1 << 28), default=99, help="coordinate range of the 8x8 run"
    )
    bench.add_argument("--json", action="store_true", help="machine-readable output")
    bench.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    bench.set_defaults(func=_bench_link)

    demo = sub.add_parser("radio-demo", help="the demo's comparison over simulated LoRa profiles")
    demo.set_defaults(func=lambda a: _radio_demo())

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
        "--px4-speed",
        type=cli.number(0, 100, above=True),
        default=None,
        help="largest SIH speed factor, the replay's time scale with --px4 (default: 5, at "
        "which two vehicles, their companions and the protocol keep up on 2 cores)",
    )
    _log_flags(replay, "companions' log on stderr (default: warning)")
    replay.set_defaults(func=_replay)

    run = sub.add_parser("run", help="the companion process beside one autopilot")
    run.add_argument(
        "--config", type=cli.existing_file, help="TOML settings, [identity] and [trust] included"
    )
    run.add_argument("--node", type=cli.integer(1, 0xFFFE), help="node id on the radio")
    run.add_argument("--autopilot", help="MAVSDK URL, e.g. udpin://0.0.0.0:14540")
    run.add_argument("--transport", choices=["udp", "serial"], help="link transport")
    run.add_argument("--profile", type=_profile, help=f"link profile: {', '.join(PROFILES)}")
    run.add_argument("--hub", help="link hub HOST:PORT (udp transport)")
    run.add_argument("--serial", help="serial device of the LoRa modem")
    run.add_argument("--offset", type=cli.number(0, 500, above=True), help="altitude offset, m")
    run.add_argument(
        "--max-altitude", type=cli.number(0, 10_000, above=True), help="metres above home"
    )
    _log_flags(run, "log level (default: the config's, else info)")
    run.set_defaults(func=_run_command)

    keys_cli.add_parser(sub)
    cli.add_common(parser)
    return parser


def _radio_demo() -> int:
    from .sim.over_link import radio_demo

    return radio_demo()


def _run_command(args: argparse.Namespace) -> int:
    return asyncio.run(_run(args))


def main(argv: list[str] | None = None) -> int:
    from .autopilot import AutopilotError
    from .link.arq import LinkError
    from .sim.px4 import Px4Error

    args = _parser().parse_args(argv)
    return cli.run(args.func, args, (AutopilotError, LinkError, Px4Error))


if __name__ == "__main__":
    sys.exit(main())
