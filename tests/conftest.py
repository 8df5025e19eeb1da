"""Shared fixtures: one real key set and one real OT setup per test session (112-bit floor);
the paper's benchmark files where they are, and data of their shape made by the project."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from protocol.ot.setup import ChooserSetup, HolderSetup, HolderSetupStart, chooser_setup
from protocol.paper.keys import DGK_BITS, BobKeys
from protocol.primitives.dgk import DGKPrivateKey, DGKPublicKey
from protocol.primitives.paillier import PaillierPrivateKey, PaillierPublicKey
from tests.paper_shaped import (
    ANCHOR,
    ANCHOR_PAIR_BITS,
    ANCHOR_ROUTE_HITS,
    PaperShaped,
    write_paper_shaped,
)

REALTIME = "realtime"  # the replays over MAVSDK, in scaled real time


def pytest_collection_finish(session: pytest.Session) -> None:
    """Under ``--dist loadgroup`` every grouped test's node id must carry its group (that is
    how pytest-xdist keeps a group on one worker); a pytest whose node ids it cannot mark
    would run the replays beside each other and the CPU-heavy tests without a word: refuse
    to run."""
    config = session.config
    if not (os.environ.get("PYTEST_XDIST_WORKER") and config.getvalue("loadgroup")):
        return
    for item in session.items:
        if any(True for _ in item.iter_markers("xdist_group")) and "@" not in item.nodeid:
            raise pytest.UsageError(
                f"pytest-xdist did not group {item.nodeid} (pytest {pytest.__version__}): "
                "xdist_group is ignored; see the pytest pin in pyproject.toml"
            )


_niced = False


@pytest.fixture(autouse=True)
def _yield_to_replays(request: pytest.FixtureRequest) -> Iterator[None]:
    """Under ``make test`` one worker takes the real-time replays first (their group is the
    largest unit of work: pytest-xdist hands it out first), and every other test runs at a
    lower priority (nice 10, from a worker's first such test on): the replays' mock
    vehicles, companions and MAVSDK servers, which must keep up with scaled real time, get
    the processor first when both workers want it.  (Only under xdist; a plain ``pytest``
    run is left as it is.)"""
    global _niced
    groups = {m.args[0] for m in request.node.iter_markers("xdist_group") if m.args}
    if not _niced and REALTIME not in groups and os.environ.get("PYTEST_XDIST_WORKER"):
        os.nice(10)
        _niced = True
    yield


@dataclass(frozen=True)
class Keys:
    """Bob's private keys, and Alice's copies of the public keys decoded from bytes."""

    paillier: PaillierPrivateKey
    dgk: DGKPrivateKey
    paillier_pub: PaillierPublicKey
    dgk_pub: DGKPublicKey

    @property
    def bob(self) -> BobKeys:
        return BobKeys(self.paillier, self.dgk)


@pytest.fixture(scope="session")
def keys() -> Keys:
    paillier = PaillierPrivateKey.generate()
    dgk = DGKPrivateKey.generate(comparison_bits=DGK_BITS)
    return Keys(
        paillier,
        dgk,
        PaillierPublicKey.from_bytes(paillier.public_key.to_bytes()),
        DGKPublicKey.from_bytes(dgk.public_key.to_bytes()),
    )


@dataclass(frozen=True)
class OtPair:
    """One OT setup between two drones: Bob's (chooser) and Alice's (Delta holder) halves."""

    chooser: ChooserSetup
    holder: HolderSetup

    @property
    def setups(self) -> dict[bytes, ChooserSetup]:
        return {self.chooser.setup_id: self.chooser}


@pytest.fixture(scope="session")
def ot_pair() -> OtPair:
    start = HolderSetupStart()
    chooser, reply = chooser_setup(start.message(), start.blocks)
    return OtPair(chooser, start.finish(reply))


@pytest.fixture(scope="session")
def anchor_data() -> Path:
    """The paper's own benchmark files, read from ``../shared/anchor-data`` (never carried)."""
    if not (ANCHOR / "alices_segments.txt").is_file():
        pytest.skip(
            "the paper's benchmark files are not beside the repository (../shared/anchor-data)"
        )
    return ANCHOR


@pytest.fixture(scope="session")
def paper_shaped(tmp_path_factory: pytest.TempPathFactory) -> PaperShaped:
    """The project's own data in the paper's layout, with answers (:mod:`tests.paper_shaped`)."""
    return write_paper_shaped(tmp_path_factory.mktemp("paper-shaped"), seed=25)


@pytest.fixture(params=["paper's files", "project's own"])
def benchmark_data(request: pytest.FixtureRequest) -> PaperShaped:
    """The paper's files with their published answers (skipped where they are not), then the
    project's own data of the same shape."""
    if request.param == "paper's files":
        directory = request.getfixturevalue("anchor_data")
        return PaperShaped(directory, ANCHOR_PAIR_BITS, ANCHOR_ROUTE_HITS)
    result: PaperShaped = request.getfixturevalue("paper_shaped")
    return result
