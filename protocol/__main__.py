"""Command line: ``python -m protocol {demo, compare, bench crypto|paper|scaling}``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .errors import ProtocolError


def _demo(_args: argparse.Namespace) -> int:
    from .demo import run_demo

    return run_demo()


def _compare(args: argparse.Namespace) -> int:
    from .compare import compare, format_compare

    result = compare(args.alice, args.bob, args.suite, range_=args.range, progress=not args.json)
    print(json.dumps(result, indent=2) if args.json else format_compare(result))
    return 0 if all(c["hits"] == c["plain_hits"] for c in result["cases"]) else 1


def _sizes(text: str | None, *, default: tuple[int, ...]) -> tuple[int, ...]:
    if text is None:
        return default
    try:
        sizes = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise ProtocolError(f"--sizes must be comma-separated integers, got {text!r}") from None
    if not sizes or any(not 1 <= s <= 256 for s in sizes):
        raise ProtocolError("--sizes must be between 1 and 256")
    return sizes


def _bench(args: argparse.Namespace) -> int:
    result: dict[str, object]
    if args.what == "crypto":
        from .bench import bench_crypto, format_crypto

        result = bench_crypto(repeat=args.repeat or 15, progress=not args.quiet)
        text = format_crypto(result)
    elif args.what == "paper":
        from .bench_paths import DEFAULT_DATA, bench_paper, format_paper

        data = Path(args.data) if args.data else DEFAULT_DATA
        result = bench_paper(data, args.suite, progress=not args.quiet)
        text = format_paper(result)
    elif args.what == "design":
        from .bench_paths import bench_design, format_design

        result = bench_design(
            _sizes(args.sizes, default=(8,))[0], args.range or 99, progress=not args.quiet
        )
        text = format_design(result)
    else:
        from .bench_paths import bench_scaling, format_scaling

        sizes = _sizes(args.sizes, default=(1, 2, 4, 8, 16, 32))
        result = bench_scaling(
            sizes, args.suite, args.range or 99, progress=not args.quiet, repeat=args.repeat or 3
        )
        text = format_scaling(result)
    print(json.dumps(result, indent=2) if args.json else text)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m protocol", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="two-drone demonstration")
    demo.set_defaults(func=_demo)

    compare = sub.add_parser("compare", help="run the encrypted path comparison on two files")
    compare.add_argument("alice", help="Alice's paths: paper format (x,y)(x,y)... or .plan")
    compare.add_argument("bob", help="Bob's paths, same format as Alice's")
    compare.add_argument("--suite", choices=["compact", "paper"], default="compact")
    compare.add_argument("--range", type=int, default=None, help="public grid range R")
    compare.add_argument("--json", action="store_true", help="machine-readable output")
    compare.set_defaults(func=_compare)

    bench = sub.add_parser("bench", help="benchmarks that print tables")
    bench.add_argument(
        "what",
        choices=["crypto", "paper", "scaling", "design"],
        help="what to measure",
    )
    bench.add_argument("--suite", choices=["compact", "paper"], default="compact")
    bench.add_argument("--data", help="directory with the paper's data (paper)")
    bench.add_argument(
        "--sizes",
        default=None,
        help="n = m values, comma-separated (scaling; default 1,2,4,8,16,32), or the one size "
        "(design; default 8)",
    )
    bench.add_argument("--range", type=int, default=None, help="coordinate range (scaling)")
    bench.add_argument("--json", action="store_true", help="machine-readable output")
    bench.add_argument(
        "--repeat", type=int, default=None, help="runs per median (crypto: 15, scaling: 3)"
    )
    bench.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    bench.set_defaults(func=_bench)
    args = parser.parse_args(argv)
    if getattr(args, "repeat", None) is not None and args.repeat < 1:
        parser.error("--repeat must be at least 1")
    try:
        code: int = args.func(args)
    except ProtocolError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return code


if __name__ == "__main__":
    sys.exit(main())
