"""Command line: ``python -m protocol {demo, bench crypto}``."""

from __future__ import annotations

import argparse
import json
import sys

from .errors import ProtocolError


def _demo(_args: argparse.Namespace) -> int:
    from .demo import run_demo

    return run_demo()


def _bench(args: argparse.Namespace) -> int:
    from .bench import bench_crypto, format_crypto

    result = bench_crypto(repeat=args.repeat, progress=not args.quiet)
    print(json.dumps(result, indent=2) if args.json else format_crypto(result))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m protocol", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="demonstrate the cryptographic core on both back-ends")
    demo.set_defaults(func=_demo)
    bench = sub.add_parser("bench", help="benchmarks that print tables")
    bench.add_argument("suite", choices=["crypto"], help="what to measure")
    bench.add_argument("--json", action="store_true", help="machine-readable output")
    bench.add_argument("--repeat", type=int, default=15, help="runs per median (default 15)")
    bench.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    bench.set_defaults(func=_bench)
    args = parser.parse_args(argv)
    if getattr(args, "repeat", 1) < 1:
        parser.error("--repeat must be at least 1")
    try:
        code: int = args.func(args)
    except ProtocolError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return code


if __name__ == "__main__":
    sys.exit(main())
