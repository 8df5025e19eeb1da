"""The paper's benchmark files, read from where they are (``--data DIR``), never carried here.

The paper's authors published their benchmark inputs beside their code (MIT): 30 single-segment
pairs (``alices_segments.txt`` / ``bobs_segments.txt``, line k against line k) and five route
tests (``ownroute{1..5}.txt`` for Alice, ``cryptroute{1..5}.txt`` for Bob, and
``testroutine.csv`` with the expected "any intersection" per route).  The project reads them
from a directory the user names -- on the project's machines ``../shared/anchor-data`` -- and
makes its own data of the same shape where it needs no more than the shape (the tests).
"""

from __future__ import annotations

import csv
import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path

from protocol.geo.grid import GridKind, GridSpec
from protocol.geo.volumes import NO_SEPARATION, Separation
from protocol.tools.compare import Case, load_cases
from protocol.tools.formats import InputFormatError, read_text

PAIR_FILES = ("alices_segments.txt", "bobs_segments.txt")
ROUTES = range(1, 6)
EXPECTED_FILE = "testroutine.csv"
HINT = (
    "the paper's benchmark files (alices_segments.txt, bobs_segments.txt, ownroute1-5.txt, "
    "cryptroute1-5.txt, testroutine.csv), published with the paper's code; the project does "
    "not carry them: on the project's machines they are in ../shared/anchor-data"
)
_ROUTE_IN_CSV = re.compile(r"ownroute(\d+)\.txt$")


@dataclass(frozen=True)
class Route:
    """One route test: Alice's and Bob's polylines and the expected "any intersection"
    (``None`` when ``testroutine.csv`` does not name the route)."""

    number: int
    case: Case
    expected_any: bool | None


@dataclass(frozen=True)
class PaperData:
    """The pairs and the route tests of one data directory."""

    directory: Path
    pairs: list[Case]
    routes: list[Route]


def check_directory(directory: Path) -> Path:
    """``directory`` holds the pair files (raises :class:`InputFormatError` saying what they
    are and where they come from)."""
    if not directory.is_dir():
        raise InputFormatError(f"{directory}: not a directory ({HINT})")
    missing = [name for name in PAIR_FILES if not (directory / name).is_file()]
    if missing:
        raise InputFormatError(f"{directory}: no {' or '.join(missing)} ({HINT})")
    return directory


def _expected_any(path: Path) -> dict[int, bool]:
    """``testroutine.csv``: rows ``.../ownrouteK.txt,.../cryptrouteK.txt,true|false``."""
    expected: dict[int, bool] = {}
    for number, row in enumerate(csv.reader(read_text(path).splitlines()), start=1):
        if not row:
            continue
        match = _ROUTE_IN_CSV.search(row[0].strip()) if len(row) == 3 else None
        answer = row[2].strip().lower() if len(row) == 3 else ""
        if match is None or answer not in ("true", "false"):
            raise InputFormatError(
                f"{path}:{number}: expected ownrouteK.txt,cryptrouteK.txt,true|false, got {row!r}"
            )
        expected[int(match.group(1))] = answer == "true"
    return expected


def load_paper_data(directory: str | Path, separation: Separation = NO_SEPARATION) -> PaperData:
    """The pairs (each on the grid of the pair files' extent) and the route tests that are
    present (all on one grid, the routes' common extent), compared with ``separation`` (the
    grids leave room for it)."""
    directory = check_directory(Path(directory))
    pairs = load_cases(*(directory / name for name in PAIR_FILES), separation=separation)
    expected = (
        _expected_any(directory / EXPECTED_FILE) if (directory / EXPECTED_FILE).exists() else {}
    )
    found = []
    for k in ROUTES:
        own, crypt = directory / f"ownroute{k}.txt", directory / f"cryptroute{k}.txt"
        if own.exists() or crypt.exists():
            if not (own.exists() and crypt.exists()):
                raise InputFormatError(
                    f"{directory}: route {k} needs both {own.name} and {crypt.name}"
                )
            found.append((k, load_cases(own, crypt, separation=separation)[0]))
    span = max((case.grid.range for _, case in found), default=1)
    grid = GridSpec(GridKind.PLANE, span)
    routes = [Route(k, dataclasses.replace(c, grid=grid), expected.get(k)) for k, c in found]
    return PaperData(directory, pairs, routes)
