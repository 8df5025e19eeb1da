"""Command line of the cryptographic core (``drone-deconflict-protocol`` or
``python -m protocol``): demo, compare, bench crypto|paper|scaling|design.  Errors are one
line and exit 2 (:mod:`protocol.tools.cli`)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any, TypeAlias

from protocol.geo.volumes import MAX_SEPARATION
from protocol.tools import cli

DESCRIPTION = (
    "The encrypted path-intersection protocol of private drone deconfliction: Alice learns "
    "which of her segments cross Bob's path, Bob learns nothing. Demo, comparison of two "
    "path files, and benchmarks."
)

# The comparison over the simulated radio is the companion's (python -m companion compare).
RADIO_OPTIONS = ("--link", "--loss", "--corrupt", "--seed", "--mtu")
MOVED = (
    f"the radio options ({', '.join(RADIO_OPTIONS)}) moved to `python -m companion compare` "
    "(drone-deconflict compare)"
)


def _demo(_args: argparse.Namespace) -> int:
    from protocol.tools.demo import run_demo

    return run_demo()


def _compare(args: argparse.Namespace) -> int:
    from protocol.geo.volumes import Separation
    from protocol.tools.compare import compare, format_compare

    result = compare(
        args.alice,
        args.bob,
        args.suite,
        range_=args.range,
        progress=not args.json,
        separation=Separation(args.separation, args.vertical_separation),
        time_tolerance=args.time_tolerance,
    )
    print(json.dumps(result, indent=2) if args.json else format_compare(result))
    return 0 if all(c["hits"] == c["plain_hits"] for c in result["cases"]) else 1


def _bench(args: argparse.Namespace) -> int:
    from protocol.geo.volumes import Separation

    result: dict[str, object]
    if args.what == "crypto":
        from protocol.tools.bench import bench_crypto, format_crypto

        result = bench_crypto(repeat=args.repeat or 15, progress=not args.quiet)
        text = format_crypto(result)
    elif args.what == "paper":
        from protocol.tools.bench_paths import bench_paper, format_paper
        from protocol.tools.paper_data import HINT

        if args.data is None:
            raise cli.InputError(f"bench paper: --data DIR is needed ({HINT})")
        result = bench_paper(
            args.data, args.suite, progress=not args.quiet, separation=Separation(args.separation)
        )
        text = format_paper(result)
    elif args.what == "design":
        from protocol.tools.bench_paths import bench_design, format_design

        result = bench_design((args.sizes or (8,))[0], args.range or 99, progress=not args.quiet)
        text = format_design(result)
    else:
        from protocol.tools.bench_paths import bench_scaling, format_scaling

        sizes = args.sizes or (1, 2, 4, 8, 16, 32)
        result = bench_scaling(
            sizes,
            args.suite,
            args.range or 99,
            progress=not args.quiet,
            repeat=args.repeat or 3,
            separation=Separation(args.separation),
        )
        text = format_scaling(result)
    print(json.dumps(result, indent=2) if args.json else text)
    return 0


Subparsers: TypeAlias = "argparse._SubParsersAction[Any]"  # the subcommands


def _add_demo(sub: Subparsers) -> None:
    demo = sub.add_parser("demo", help="two-drone demonstration")
    demo.set_defaults(func=_demo)


def _add_compare(sub: Subparsers) -> None:
    compare = sub.add_parser("compare", help="run the encrypted path comparison on two files")
    compare.add_argument(
        "alice",
        type=cli.existing_file,
        help="Alice's paths: paper format (x,y)(x,y)..., or (x,y,z) / (x,y,z,t) vertices",
    )
    compare.add_argument("bob", type=cli.existing_file, help="Bob's paths, same format")
    compare.add_argument(
        "--suite", choices=["compact", "paper"], default="compact", help="cryptographic suite"
    )
    compare.add_argument(
        "--range",
        type=cli.integer(1, 1 << 28),
        default=None,
        help="public grid range R (default: the files' extent)",
    )
    compare.add_argument(
        "--separation",
        type=cli.integer(0, MAX_SEPARATION),
        default=0,
        help="horizontal separation r in grid units: segments within r conflict (0: the "
        "paper's crossing test)",
    )
    compare.add_argument(
        "--vertical-separation",
        type=cli.integer(0, MAX_SEPARATION),
        default=0,
        help="vertical separation in grid units: altitude bands within it conflict (vertices "
        "written (x,y,z) give the bands)",
    )
    compare.add_argument(
        "--time-tolerance",
        type=cli.integer(0, 1 << 20),
        default=0,
        help="seconds each time window is widened by on either side (vertices written "
        "(x,y,z,t) give the windows)",
    )
    compare.add_argument("--json", action="store_true", help="machine-readable output")
    for option in RADIO_OPTIONS:
        compare.add_argument(option, action=cli.Moved, to=MOVED)
    compare.set_defaults(func=_compare)


def _add_bench(sub: Subparsers) -> None:
    bench = sub.add_parser("bench", help="benchmarks that print tables")
    bench.add_argument(
        "what",
        choices=["crypto", "paper", "scaling", "design"],
        help="what to measure",
    )
    bench.add_argument(
        "--suite", choices=["compact", "paper"], default="compact", help="cryptographic suite"
    )
    bench.add_argument(
        "--data",
        type=cli.existing_dir,
        default=None,
        help="directory with the paper's benchmark files (paper; needed: the project does not "
        "carry them, e.g. ../shared/anchor-data)",
    )
    bench.add_argument(
        "--sizes",
        type=cli.integers(1, 256),
        default=None,
        help="n = m values, comma-separated (scaling; default 1,2,4,8,16,32), or the one size "
        "(design; default 8)",
    )
    bench.add_argument(
        "--range",
        type=cli.integer(1, 1 << 28),
        default=None,
        help="coordinate range (scaling, design; default 99)",
    )
    bench.add_argument(
        "--separation",
        type=cli.integer(0, MAX_SEPARATION),
        default=0,
        help="horizontal separation in grid units (paper, scaling; compact suite; 0: the "
        "crossing test)",
    )
    bench.add_argument("--json", action="store_true", help="machine-readable output")
    bench.add_argument(
        "--repeat",
        type=cli.integer(1, 1000),
        default=None,
        help="runs per median (default: crypto 15, scaling 3)",
    )
    bench.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    bench.set_defaults(func=_bench)


def _parser() -> argparse.ArgumentParser:
    """The command line: one function per subcommand."""
    parser = cli.Parser(prog="drone-deconflict-protocol", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_demo(sub)
    _add_compare(sub)
    _add_bench(sub)
    cli.add_common(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    return cli.run(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
