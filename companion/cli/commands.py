"""What each ``drone-deconflict`` command does (the parser and ``main`` are in
``companion/__main__.py``).  Commands raise on failure; :func:`protocol.tools.cli.run` turns
expected failures into one line and exit 2."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import signal
import sys
from typing import TYPE_CHECKING, Any

from companion import logs
from companion.radio import Clock
from companion.radio.airtime import PHY_MAX_FRAME
from companion.sim.medium import Channel, Impairments
from companion.sim.udp_hub import UdpHub
from protocol.tools import cli

if TYPE_CHECKING:
    from companion.app.config import LinkSettings
    from companion.radio.transport import Transport

DEFAULT_HOME = (47.397742, 8.545594, 488.0)  # PX4 SITL's default home


def _stop_on_signals() -> asyncio.Event:
    """An event set by SIGINT/SIGTERM (install before announcing readiness)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    return stop


async def hub(args: argparse.Namespace) -> int:
    impairments = Impairments(
        loss=args.loss,
        corrupt=args.corrupt,
        duplicate=args.duplicate,
        reorder=args.reorder,
        latency_s=args.latency,
    )
    channel = Channel(impairments, args.seed, collisions=not args.no_collisions)
    try:
        hub = await UdpHub.serve(channel, args.host, args.port, Clock(args.time_scale))
    except OSError as exc:  # the address is taken, or not this machine's
        raise cli.InputError(f"--host {args.host} --port {args.port}: {cli.describe(exc)}") from exc
    host, port = hub.address
    stop = _stop_on_signals()
    print(f"link hub on udp://{host}:{port} ({impairments})", flush=True)
    await stop.wait()
    hub.close()
    print(f"hub stopped: {channel.stats}", flush=True)
    return 0


async def mock(args: argparse.Namespace) -> int:
    from companion.mission.files import read_mission_file
    from companion.sim.mock_autopilot import Faults, FlightModel, MockAutopilot

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
        drop_every=args.drop_every or 0,
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
        from companion.sim.export import tracks_csv

        cli.write_atomic(args.trajectory, tracks_csv({0: mock.trajectory}))
    return 0


def mission_show(args: argparse.Namespace) -> int:
    from pymavlink.dialects.v20 import common as mavlink

    from companion.mission.files import read_mission_file
    from companion.mission.flightpath import flight_path
    from companion.mission.items import MissionError

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


def _run_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``run`` options as configuration overrides (dotted keys)."""
    return {
        "node": args.node,
        "autopilot": args.autopilot,
        "log_level": args.log_level,
        "link.transport": args.transport,
        "link.profile": args.profile,
        "link.hub": args.hub,
        "link.serial": args.serial,
        "offset.offset_m": args.offset,
        "offset.max_altitude_m": args.max_altitude,
        "separation.horizontal_m": args.separation,
        "separation.vertical_m": args.vertical_separation,
    }


async def _open_transport(node: int, link: LinkSettings) -> Transport:
    """The companion's radio: a serial port, or the UDP link hub."""
    if link.transport == "serial":
        from companion.radio.serial_port import SerialTransport

        return SerialTransport.open(link.serial, link.baudrate)
    from companion.radio.udp import UdpTransport

    return await UdpTransport.connect(node, link.hub)


async def run(args: argparse.Namespace) -> int:
    import logging

    from companion.app.config import load_config
    from companion.app.runtime import Companion
    from companion.mission.autopilot import Autopilot, Timeouts
    from companion.mission.personalities import personality
    from companion.radio import LinkEndpoint, profile

    config = load_config(args.config, _run_overrides(args))
    logs.setup(config.log_level, args.log_json, mavsdk=True)
    log = logging.getLogger("companion")
    settings, link = config.companion, config.link
    if config.credentials is None:
        raise cli.InputError(
            "the companion needs an identity: [identity] key, certificate and [[trust.operator]] "
            "in --config (python -m companion keys init|certify)"
        )
    transport = await _open_transport(settings.node, link)
    endpoint = LinkEndpoint(settings.node, transport, profile(link.profile))
    log.info("node %d: connecting to the autopilot at %s", settings.node, settings.autopilot_url)
    try:
        autopilot = await Autopilot.connect(
            settings.autopilot_url,
            Timeouts(connect_s=settings.autopilot_connect_s),
            personality(settings.ardupilot),
        )
    except BaseException:
        await transport.close()  # the link's socket and keep-alive end with the error
        raise
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


def replay(args: argparse.Namespace) -> int:
    from companion.sim.export import export
    from companion.sim.plot import plot_report
    from companion.sim.px4 import Px4Error, find_build
    from companion.sim.replay import PX4_SPEED_MAX, run_replay, run_virtual
    from companion.sim.report import format_report
    from companion.sim.scenario import ScenarioError, load_scenario

    level = args.log_level or ("info" if args.log_json else "warning")
    logs.setup(level, args.log_json, stderr_level=args.log_level or "warning", mavsdk=True)
    scenario = load_scenario(args.scenario)  # all checked before anything starts
    if args.virtual and args.px4:
        raise cli.InputError("--virtual and --px4 exclude each other (PX4 SITL runs in real time)")
    try:
        build = find_build(args.px4) if args.px4 else None
    except Px4Error as exc:
        raise cli.InputError(f"PX4 SITL: {exc}") from None
    if args.virtual:
        try:
            replay = run_virtual(scenario, progress=not args.json)
        except ScenarioError as exc:
            raise cli.InputError(str(exc)) from None
    else:
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
        cli.write_atomic(args.out, json.dumps(report.to_json(), indent=2) + "\n")
    if args.plot:
        plot_report(replay, args.plot)
    if args.export:
        for path in export(replay, args.export):
            print(f"wrote {path}", file=sys.stderr)
    print(json.dumps(report.to_json(), indent=2) if args.json else format_report(report))
    return cli.EXIT_OK if report.ok else cli.EXIT_NEGATIVE


def fleet(args: argparse.Namespace) -> int:
    """The fleet simulation: a city's traffic in virtual time, summed up per drone-hour."""
    from companion.sim.city import CitySpec, city_json, format_city, run_city

    logs.setup("error", None, stderr_level="error", mavsdk=False)
    spec = CitySpec(
        drones=args.drones,
        hours=args.hours,
        area_km=args.area_km,
        range_km=args.range_km,
        seed=args.seed,
        profile=args.profile,
        loss=args.loss,
    )
    city = run_city(spec, progress=args.progress)
    if args.out:
        cli.write_atomic(args.out, json.dumps(city.replay.to_json(), indent=2) + "\n")
    print(json.dumps(city_json(city), indent=2) if args.json else format_city(city))
    return cli.EXIT_OK if city.replay.finished else cli.EXIT_NEGATIVE


def compare(args: argparse.Namespace) -> int:
    """The protocol's comparison over the simulated radio (the radio is the companion's)."""
    from companion.radio import profile
    from companion.sim.over_link import compare_over_link
    from protocol.tools.compare import format_compare

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


def bench_link(args: argparse.Namespace) -> int:
    from companion.sim.bench_link import bench_link, format_link

    profiles = list(args.profiles) if args.profiles else None
    result = bench_link(
        args.data,
        profiles,
        suite=args.suite,
        range_=args.range,
        pairs=args.pairs,
        progress=not args.quiet,
    )
    print(json.dumps(result, indent=2) if args.json else format_link(result))
    return 0


def radio_demo() -> int:
    from companion.sim.over_link import radio_demo

    return radio_demo()


def run_command(args: argparse.Namespace) -> int:
    return asyncio.run(run(args))
