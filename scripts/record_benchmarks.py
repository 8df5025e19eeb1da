"""Re-run the benchmarks and rewrite their sections of docs/benchmarks.md.

Usage: .venv/bin/python scripts/record_benchmarks.py [crypto] [paper] [paper-dgk] [scaling] [link]
(default: all) [--repeat N]

Each section sits between markers ``<!-- bench NAME -->`` and ``<!-- /bench NAME -->``; the
rest of the file is kept.  The new file is written next to the old one and renamed over it, so
an interrupted run leaves the old file intact.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from collections.abc import Callable
from pathlib import Path

from companion.over_link import bench_link, format_link
from protocol.bench import bench_crypto, format_crypto
from protocol.bench_paths import bench_paper, bench_scaling, format_paper, format_scaling

DOC = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"


def sections(repeat: int) -> dict[str, Callable[[], str]]:
    return {
        "crypto": lambda: format_crypto(bench_crypto(repeat=repeat)),
        "paper": lambda: format_paper(bench_paper(suite="compact")),
        "paper-dgk": lambda: format_paper(bench_paper(suite="paper")),
        "scaling": lambda: format_scaling(bench_scaling()),
        "link": lambda: format_link(bench_link()),
    }


def replace_section(text: str, name: str, body: str) -> str:
    start, end = f"<!-- bench {name} -->", f"<!-- /bench {name} -->"
    if start not in text or end not in text:
        return text.rstrip("\n") + f"\n\n{start}\n{body}\n{end}\n"
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{start}\n{body}\n{end}{tail}"


def main() -> int:
    table = sections(15)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"sections: {', '.join(table)} (default all)")
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args()
    unknown = set(args.names) - set(table)
    if unknown:
        parser.error(f"unknown sections: {', '.join(sorted(unknown))}")
    table = sections(args.repeat)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    text = DOC.read_text() if DOC.exists() else "# Benchmarks\n"
    for name in args.names or list(table):
        body = f"Machine: {machine}.\n\n{table[name]()}"
        print(body, flush=True)
        text = replace_section(text, name, body)
        tmp = DOC.with_suffix(".md.tmp")
        tmp.write_text(text)
        tmp.replace(DOC)
    return 0


if __name__ == "__main__":
    sys.exit(main())
