"""Re-run ``python -m protocol bench crypto`` and rewrite its section of docs/benchmarks.md.

Usage: .venv/bin/python scripts/record_benchmarks.py [--repeat N]

The section between the markers ``<!-- bench crypto -->`` and ``<!-- /bench crypto -->`` is
replaced; the rest of the file is kept.  The new file is written next to the old one and renamed
over it, so an interrupted run leaves the old file intact.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

from protocol.bench import bench_crypto, format_crypto

DOC = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
START, END = "<!-- bench crypto -->", "<!-- /bench crypto -->"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args()
    result = bench_crypto(repeat=args.repeat)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    section = f"{START}\nMachine: {machine}.\n\n{format_crypto(result)}\n{END}"
    text = DOC.read_text() if DOC.exists() else f"# Benchmarks\n\n{START}\n{END}\n"
    if START not in text or END not in text:
        print(f"error: markers missing in {DOC}", file=sys.stderr)
        return 1
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    tmp = DOC.with_suffix(".md.tmp")
    tmp.write_text(head + section + tail)
    tmp.replace(DOC)
    print(format_crypto(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
