"""Command line: ``python -m companion link-hub`` (more commands come with the companion)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys

from .link import Channel, Clock, Impairments
from .link.udp import UdpHub


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
    print(f"link hub on udp://{host}:{port} ({impairments})", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    hub.close()
    print(f"hub stopped: {channel.stats}", flush=True)
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
    args = parser.parse_args(argv)
    try:
        return asyncio.run(_hub(args))
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
