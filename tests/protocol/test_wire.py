"""Wire format: round trips, and fuzzing -- malformed input raises RemoteProtocolError only."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.errors import RemoteProtocolError
from protocol.grid import GridKind, GridSpec
from protocol.intersection import Alice, Bob, State
from protocol.loopback import run_paths
from protocol.wire import HEADER_SIZE, Hello, MsgType, Suite, frame, unframe

GRID = GridSpec(GridKind.PLANE, 99)
ALICE_PATH = ((0, 0), (10, 10), (20, 0))
BOB_PATH = ((0, 10), (10, 0))
FUZZ = settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

grids = st.builds(
    GridSpec,
    st.sampled_from(GridKind),
    st.integers(1, 1 << 28),
    st.integers(-900_000_000, 900_000_000),
    st.integers(-1_800_000_000, 1_800_000_000),
    st.integers(1, 1_000_000),
)


@given(
    suites=st.sampled_from([(Suite.COMPACT,), (Suite.PAPER,), (Suite.COMPACT, Suite.PAPER)]),
    key=st.binary(max_size=300),
    kappa=st.integers(0, 255),
    grid=grids,
    m=st.integers(0, 0xFFFF),
)
def test_hello_round_trip(suites: Any, key: bytes, kappa: int, grid: GridSpec, m: int) -> None:
    hello = Hello(suites, (key,) * len(suites), kappa, grid, m)
    assert Hello.from_bytes(hello.to_bytes()) == hello


@given(grid=grids)
def test_grid_round_trip(grid: GridSpec) -> None:
    assert GridSpec.from_bytes(grid.to_bytes()) == grid


def test_unframe_is_strict() -> None:
    good = frame(MsgType.MASKED, b"abc")
    assert unframe(good, MsgType.MASKED) == b"abc"
    for bad in (
        good[: HEADER_SIZE - 1],
        b"XX" + good[2:],
        good[:2] + b"\x09" + good[3:],
        good[:3] + bytes([MsgType.BITS]) + good[4:],
        good + b"\x00",
        good[:-1],
    ):
        with pytest.raises(RemoteProtocolError):
            unframe(bad, MsgType.MASKED)


@settings(max_examples=300)
@given(data=st.binary(max_size=200))
def test_arbitrary_bytes_as_hello(data: bytes) -> None:
    with pytest.raises(RemoteProtocolError):
        Hello.from_bytes(data)


@settings(max_examples=300)
@given(body=st.binary(max_size=120))
def test_arbitrary_hello_bodies(body: bytes) -> None:
    try:
        Hello.from_bytes(frame(MsgType.HELLO, body))
    except RemoteProtocolError:
        pass


@pytest.fixture(scope="module")
def recorded(path_keys: Any) -> list[bytes]:
    """The eight frames of one honest run."""
    frames: list[bytes] = []

    class Recorder:
        def __init__(self, machine: Any) -> None:
            self.machine = machine

        def start(self) -> bytes:
            out: bytes = self.machine.start()
            frames.append(out)
            return out

        def receive(self, data: bytes) -> bytes | None:
            out: bytes | None = self.machine.receive(data)
            if out is not None:
                frames.append(out)
            return out

    alice = Alice(ALICE_PATH, GRID, {Suite.COMPACT: path_keys.alice[Suite.COMPACT]})
    bob = Bob(BOB_PATH, path_keys.bob)
    run_paths(Recorder(alice), Recorder(bob))  # type: ignore[arg-type]
    assert len(frames) == 8
    return frames


def machine_at(step: int, frames: list[bytes], keys: Any) -> Any:
    """A fresh machine waiting for frame ``step`` (0-based), fed the recorded frames before."""
    if step % 2 == 0:  # Bob receives frames 0, 2, 4, 6
        bob = Bob(BOB_PATH, keys.bob)
        for k in range(0, step, 2):
            bob.receive(frames[k])
        return bob
    alice = Alice(ALICE_PATH, GRID, {Suite.COMPACT: keys.alice[Suite.COMPACT]})
    alice.start()
    for k in range(1, step, 2):
        alice.receive(frames[k])
    return alice


mutations = st.one_of(
    st.tuples(st.just("truncate"), st.integers(0, 1 << 20), st.just(0)),
    st.tuples(st.just("flip"), st.integers(0, 1 << 20), st.integers(1, 255)),
    st.tuples(st.just("append"), st.integers(1, 64), st.just(0)),
)


def mutate(data: bytes, mutation: tuple[str, int, int]) -> bytes:
    kind, where, value = mutation
    if kind == "truncate":
        return data[: where % len(data)]
    if kind == "append":
        return data + bytes(where)
    where %= len(data)
    return data[:where] + bytes([data[where] ^ value]) + data[where + 1 :]


@pytest.mark.slow
@pytest.mark.parametrize("step", range(1, 8))
@FUZZ
@given(mutation=mutations)
def test_mutated_frames_raise_only_the_documented_error(
    step: int, mutation: Any, recorded: list[bytes], path_keys: Any
) -> None:
    machine = machine_at(step, recorded, path_keys)
    try:
        machine.receive(mutate(recorded[step], mutation))
    except RemoteProtocolError:
        assert machine.state is State.FAILED


@pytest.mark.parametrize("step", range(1, 8))
def test_frame_bodies_of_wrong_type_or_size(
    step: int, recorded: list[bytes], path_keys: Any
) -> None:
    machine = machine_at(step, recorded, path_keys)
    with pytest.raises(RemoteProtocolError):
        machine.receive(recorded[step - 1])  # the previous frame, wrong type
    machine = machine_at(step, recorded, path_keys)
    with pytest.raises(RemoteProtocolError):
        machine.receive(recorded[step][:-1])
    assert machine.state is State.FAILED


@settings(
    max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(body=st.binary(max_size=600))
def test_arbitrary_keys_bodies(body: bytes, path_keys: Any) -> None:
    alice = Alice(ALICE_PATH, GRID, {Suite.COMPACT: path_keys.alice[Suite.COMPACT]})
    alice.start()
    with pytest.raises(RemoteProtocolError):
        alice.receive(frame(MsgType.KEYS, body))
