"""Command line: ``python -m companion {run, keys, replay, compare, bench-link, radio-demo,
link-hub, mock-autopilot, mission show}``."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import signal
import sys

from protocol.errors import ProtocolError

from . import keys_cli
from .link import Channel, Clock, Impairments
from .link.udp import UdpHub

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
    from .mock_autopilot import Faults, FlightModel, MockAutopilot

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
        with open(args.trajectory, "w", encoding="utf-8") as handle:
            handle.write("t_s,lat,lon,alt_m\n")
            for t, lat, lon, alt in mock.trajectory:
                handle.write(f"{t:.2f},{lat:.7f},{lon:.7f},{alt:.2f}\n")
    return 0


def _mission_show(args: argparse.Namespace) -> int:
    from pymavlink.dialects.v20 import common as mavlink

    from .flightpath import flight_path
    from .missionfile import read_mission_file

    plan = read_mission_file(args.file)
    items = plan.for_autopilot(ardupilot=args.ardupilot)
    home = plan.home_degE7
    path = flight_path(items, home, ardupilot=args.ardupilot)
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
    logging.basicConfig(
        level=config.log_level.upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    log = logging.getLogger("companion")
    settings, link = config.companion, config.link
    if config.credentials is None:
        raise ValueError(
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
    import json
    import logging
    from pathlib import Path

    from .replay import PX4_SPEED_MAX, format_report, load_scenario, plot_report, run_replay
    from .sim_px4 import Px4Error, find_build

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    scenario = load_scenario(args.scenario)
    try:
        build = find_build(args.px4) if args.px4 else None
        replay = asyncio.run(
            run_replay(
                scenario,
                progress=not args.json,
                px4=build,
                px4_speed_max=PX4_SPEED_MAX if args.px4_speed is None else args.px4_speed,
            )
        )
    except Px4Error as exc:
        print(f"error: PX4 SITL: {exc}", file=sys.stderr)
        return 2
    report = replay.report
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(out.suffix + ".tmp")
        tmp.write_text(json.dumps(report, indent=2) + "\n")
        tmp.replace(out)
    if args.plot:
        plot_report(replay, args.plot)
    print(json.dumps(report, indent=2) if args.json else format_report(report))
    ok = report["finished"] and report["conflicts_resolved"] == report["conflicts"]
    return 0 if ok and report["false_alarms"] == 0 else 1


def _compare(args: argparse.Namespace) -> int:
    """The protocol's comparison over the simulated radio (the radio is the companion's)."""
    from protocol.compare import format_compare

    from .link import profile
    from .over_link import compare_over_link

    link = profile(args.link)
    if args.mtu is not None:
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
    from pathlib import Path

    from protocol.bench_paths import DEFAULT_DATA

    from .over_link import bench_link, format_link

    data = Path(args.data) if args.data else DEFAULT_DATA
    profiles = args.profiles.split(",") if args.profiles else None
    result = bench_link(
        data, profiles, suite=args.suite, range_=args.range, progress=not args.quiet
    )
    print(json.dumps(result, indent=2) if args.json else format_link(result))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m companion", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    hub = sub.add_parser("link-hub", help="a simulated radio channel shared over UDP")
    hub.add_argument("--host", default="127.0.0.1")
    hub.add_argument("--port", type=int, default=14600)
    hub.add_argument("--loss", type=float, default=0.0)
    hub.add_argument("--corrupt", type=float, default=0.0)
    hub.add_argument("--duplicate", type=float, default=0.0)
    hub.add_argument("--reorder", type=float, default=0.0)
    hub.add_argument("--latency", type=float, default=0.002, help="seconds")
    hub.add_argument("--seed", type=int, default=None)
    hub.add_argument("--time-scale", type=float, default=1.0)
    hub.add_argument("--no-collisions", action="store_true")

    mock = sub.add_parser("mock-autopilot", help="a MAVLink autopilot for tests and replays")
    mock.add_argument("--mission", help=".plan or QGC WPL 110 file to start with")
    mock.add_argument("--instance", type=int, default=0, help="binds 14580+I, sends to 14540+I")
    mock.add_argument("--ardupilot", action="store_true", help="ArduPilot personality")
    home_help = "home %s (default: the mission file's home, else %s)"
    for key, default in zip(("lat", "lon", "alt"), DEFAULT_HOME, strict=True):
        mock.add_argument(
            f"--home-{key}", type=float, default=None, help=home_help % (key, default)
        )
    mock.add_argument("--speed", type=float, default=10.0, help="cruise m/s")
    mock.add_argument("--time-scale", type=float, default=1.0)
    mock.add_argument("--drop-every", type=int, default=0, help="drop every k-th mission reply")
    mock.add_argument("--latency", type=float, default=0.0, help="seconds added to replies")
    mock.add_argument("--ignore", action="append", help="MAVLink message name to ignore")
    mock.add_argument("--reject-upload", type=int, default=None, help="MAV_MISSION_RESULT")
    mock.add_argument("--vanish-after", type=float, default=None, help="seconds")
    mock.add_argument("--trajectory", help="write the flown trajectory (CSV) on exit")

    mission = sub.add_parser("mission", help="mission files")
    mission_sub = mission.add_subparsers(dest="action", required=True)
    show = mission_sub.add_parser("show", help="print a mission and its segments")
    show.add_argument("file")
    show.add_argument("--ardupilot", action="store_true", help="item 0 is home")

    compare = sub.add_parser("compare", help="the encrypted path comparison over the radio link")
    compare.add_argument(
        "alice",
        help="Alice's paths: paper format (x,y)(x,y)..., or a mission file (.plan, QGC WPL): "
        "the path it flies",
    )
    compare.add_argument("bob", help="Bob's paths, same format as Alice's")
    compare.add_argument(
        "--link",
        metavar="PROFILE",
        required=True,
        help="eu868-sf7, eu868-sf9, eu868-sf12, eu868-g3-sf7, us915-sf7, us915-sf9 or ideal",
    )
    compare.add_argument("--suite", choices=["compact", "paper"], default="compact")
    compare.add_argument("--range", type=int, default=None, help="public grid range R")
    compare.add_argument("--loss", type=float, default=0.0, help="frame loss probability")
    compare.add_argument("--corrupt", type=float, default=0.0, help="frame corruption probability")
    compare.add_argument("--seed", type=int, default=None, help="channel seed")
    compare.add_argument("--mtu", type=int, default=None, help="radio frame size, 32..255 bytes")
    compare.add_argument("--json", action="store_true", help="machine-readable output")

    bench = sub.add_parser("bench-link", help="the paper's pairs and an 8x8 run over each profile")
    bench.add_argument("--data", help="directory with the paper's data")
    bench.add_argument("--profiles", help="comma-separated link profiles (default all)")
    bench.add_argument("--suite", choices=["compact", "paper"], default="compact")
    bench.add_argument("--range", type=int, default=99, help="coordinate range of the 8x8 run")
    bench.add_argument("--json", action="store_true", help="machine-readable output")
    bench.add_argument("--quiet", action="store_true", help="no progress lines on stderr")

    sub.add_parser("radio-demo", help="the demo's comparison over simulated LoRa profiles")

    replay = sub.add_parser("replay", help="fly a scenario: mock autopilots, MAVSDK, companions")
    replay.add_argument("scenario", help="scenario TOML (see sitl_configs/scenarios/)")
    replay.add_argument("--json", action="store_true", help="print the report as JSON")
    replay.add_argument("--out", help="also write the JSON report to this file")
    replay.add_argument("--plot", help="write a PNG: ground tracks and altitude profiles")
    replay.add_argument(
        "--px4",
        metavar="DIR",
        help="fly PX4 SITL (SIH) vehicles from the build in DIR (bin/px4, etc/) instead of mocks",
    )
    replay.add_argument(
        "--px4-speed",
        type=float,
        default=None,
        help="largest SIH speed factor, the replay's time scale with --px4 (default 5: two "
        "vehicles, their companions and the protocol keep up on 2 cores)",
    )

    run = sub.add_parser("run", help="the companion process beside one autopilot")
    run.add_argument("--config", help="TOML settings, [identity] and [trust] included")
    run.add_argument("--node", type=int, help="node id on the radio")
    run.add_argument("--autopilot", help="MAVSDK URL, e.g. udpin://0.0.0.0:14540")
    run.add_argument("--transport", choices=["udp", "serial"], help="link transport")
    run.add_argument("--profile", help="link profile, e.g. us915-sf7")
    run.add_argument("--hub", help="link hub HOST:PORT (udp transport)")
    run.add_argument("--serial", help="serial device of the LoRa modem")
    run.add_argument("--offset", type=float, help="altitude offset in metres")
    run.add_argument("--max-altitude", type=float, help="metres above home")
    run.add_argument("--log-level", choices=["debug", "info", "warning", "error"])

    keys_cli.add_parser(sub)

    args = parser.parse_args(argv)
    if args.command == "keys":
        return keys_cli.run(args)
    try:
        if args.command == "run":
            from .autopilot import AutopilotError

            try:
                return asyncio.run(_run(args))
            except AutopilotError as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 1
        if args.command == "replay":
            return _replay(args)
        if args.command == "compare":
            return _compare(args)
        if args.command == "bench-link":
            return _bench_link(args)
        if args.command == "radio-demo":
            from .over_link import radio_demo

            return radio_demo()
        if args.command == "link-hub":
            return asyncio.run(_hub(args))
        if args.command == "mock-autopilot":
            return asyncio.run(_mock(args))
        return _mission_show(args)
    except (ValueError, OSError, ProtocolError) as exc:  # MissionError is a ValueError
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
