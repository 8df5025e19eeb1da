"""What a run of either suite is: its limits, its public layout and the machines' common
state handling (Alice's and Bob's sides) and how Bob's path enters.

Both suites (:mod:`protocol.compact.suite`, :mod:`protocol.paper.suite`) build on these types,
and :mod:`protocol.intersection` picks a suite for Alice's hello; the types live here so that
neither imports the other.  Both paths are padded to a public size (next power of two by
default) by repeating the last vertex, which changes no answer.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from protocol.circuits.boolean import Circuit
from protocol.circuits.paths import Capsules, Orient, Proj, Range, volume_hits
from protocol.errors import InputRangeError, LocalProtocolError, RemoteProtocolError
from protocol.geo.geometry import BobPath, Point, fit_to_box
from protocol.geo.grid import GridKind
from protocol.geo.volumes import (
    MAX_SEPARATION,
    Route,
    as_route,
)
from protocol.messages import Hello

W = TypeVar("W")

MAX_SEGMENTS = 256


@dataclass(frozen=True, slots=True)
class Limits:
    """Public size policy.  ``max_segments`` bounds n and m (the probing attack needs many);
    ``pad_to_power_of_two`` hides a path's exact length inside its power-of-two bucket;
    ``max_separation`` bounds the horizontal separation a peer may ask for (grid units)."""

    max_segments: int = MAX_SEGMENTS
    pad_to_power_of_two: bool = True
    max_separation: int = MAX_SEPARATION

    def padded(self, segments: int) -> int:
        if not 1 <= segments <= self.max_segments:
            raise InputRangeError(f"{segments} segments outside 1..{self.max_segments}")
        if not self.pad_to_power_of_two:
            return segments
        return min(1 << (segments - 1).bit_length(), self.max_segments)

    def public_size(self, segments: int) -> int:
        """The size a run shows for a path of ``segments`` segments: padded, and cut to
        ``max_segments`` (the path's tail waits for a later run); the one rule for it."""
        return self.padded(min(max(segments, 1), self.max_segments))

    def peer_size(self, segments: int, asked: int = 0) -> int:
        """The size the peer announces for its path, refused outside 1..max_segments, and
        unless it is the size asked for (``asked``: Alice's ``Hello.n``, 0 for none)."""
        if not 1 <= segments <= self.max_segments:
            raise RemoteProtocolError(f"peer's path has {segments} segments")
        if asked and segments != asked:
            raise RemoteProtocolError(f"peer answered {segments} segments, {asked} were asked")
        return segments


DEFAULT_LIMITS = Limits()


def check_ask(n: int, limits: Limits) -> int:
    """The size Alice asks of Bob's path (``Hello.n``): 0 (none) or 1..max_segments."""
    if not 0 <= n <= limits.max_segments:
        raise InputRangeError(f"a size of {n} segments asked, outside 0..{limits.max_segments}")
    return n


class Kind(enum.IntEnum):
    """The linear forms a run computes (:mod:`protocol.geo.geometry`,
    :mod:`protocol.geo.volumes`)."""

    O1 = 0  # orient(A_i, A_i+1, B_k): Alice segment i, Bob vertex k
    T = 1  # projection of Bob vertex k on Alice segment i
    O3 = 2  # orient(B_k, B_k+1, A_j): Bob segment k, Alice vertex j
    T3 = 3  # (A_j - B_k) . (B_k+1 - B_k): Alice vertex j along Bob segment k (capsules)
    D = 4  # |A_j - B_k|^2: Alice vertex j, Bob vertex k (capsules)


@dataclass(frozen=True, slots=True)
class Wires:
    """What the comparisons of one form give the circuit: ``orient`` (O1, O3), ``proj`` (T),
    ``near`` (|O1| <= R_i, |O3| <= R'_k, 0 <= T3 <= L_k: capsules) and ``disc`` (D <= r^2)."""

    orient: Orient | None = None
    proj: Proj | None = None
    near: Range | None = None
    disc: int | None = None


@dataclass(frozen=True)
class Layout:
    """The forms of an m x n run, in their public order: every O1, every T, every O3, each row
    by row; with ``capsules`` (a horizontal separation r > 0) then every T3 and every D.
    ``bands`` and ``windows``: the run also compares altitude bands and time windows, per
    segment pair (no forms: each party's own numbers)."""

    m: int
    n: int
    capsules: bool = False
    bands: bool = False
    windows: bool = False
    values: tuple[tuple[Kind, int, int], ...] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", tuple(v for kind in self.kinds for v in self._of(kind)))

    @property
    def kinds(self) -> tuple[Kind, ...]:
        crossing = (Kind.O1, Kind.T, Kind.O3)
        return crossing + ((Kind.T3, Kind.D) if self.capsules else ())

    def _shape(self, kind: Kind) -> tuple[int, int]:
        """(rows, columns) of a kind: Alice's segments or vertices, Bob's vertices or segments."""
        m, n = self.m, self.n
        return {
            Kind.O1: (m, n + 1),
            Kind.T: (m, n + 1),
            Kind.O3: (m + 1, n),
            Kind.T3: (m + 1, n),
            Kind.D: (m + 1, n + 1),
        }[kind]

    def _of(self, kind: Kind) -> list[tuple[Kind, int, int]]:
        rows, cols = self._shape(kind)
        return [(kind, row, col) for row in range(rows) for col in range(cols)]

    def position(self, kind: Kind, row: int, col: int) -> int:
        start = 0
        for other in self.kinds:
            rows, cols = self._shape(other)
            if other is kind:
                return start + row * cols + col
            start += rows * cols
        raise LocalProtocolError(f"this run has no {kind.name} values")

    def pairs(self) -> list[tuple[int, int]]:
        """Alice's segment i and Bob's segment k, row by row: the order of band and window
        comparisons."""
        return [(i, k) for i in range(self.m) for k in range(self.n)]

    def outputs(
        self,
        circuit: Circuit,
        wires: Sequence[Wires],
        bands: Sequence[Range] | None = None,
        windows: Sequence[Range] | None = None,
    ) -> None:
        """Add the conflict circuit (:func:`protocol.circuits.paths.volume_hits`) on the per-form
        ``wires`` (indexed by position) and the per-pair ``bands`` and ``windows`` (in
        :meth:`pairs` order), and Bob's flag as the circuit's last input (Alice's share 0)."""

        def grid(kind: Kind, pick: Callable[[Wires], W | None]) -> list[list[W]]:
            rows, cols = self._shape(kind)
            out: list[list[W]] = []
            for row in range(rows):
                line = []
                for col in range(cols):
                    value = pick(wires[self.position(kind, row, col)])
                    if value is None:
                        raise LocalProtocolError(f"no wire for {kind.name} ({row}, {col})")
                    line.append(value)
                out.append(line)
            return out

        def per_pair(ranges: Sequence[Range] | None) -> list[list[Range]] | None:
            if ranges is None:
                return None
            return [list(ranges[i * self.n : (i + 1) * self.n]) for i in range(self.m)]

        capsules = None
        if self.capsules:
            capsules = Capsules(
                near1=grid(Kind.O1, lambda w: w.near),
                near3=grid(Kind.O3, lambda w: w.near),
                along3=grid(Kind.T3, lambda w: w.near),
                disc=grid(Kind.D, lambda w: w.disc),
            )
        hits = volume_hits(
            circuit,
            self.m,
            self.n,
            grid(Kind.O1, lambda w: w.orient),
            grid(Kind.T, lambda w: w.proj),
            grid(Kind.O3, lambda w: w.orient),
            capsules=capsules,
            bands=per_pair(bands),
            windows=per_pair(windows),
            flag=circuit.input(),
        )
        for wire in hits:
            circuit.output(wire)


class State(enum.Enum):
    START = "start"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"


class Machine:
    """Shared bookkeeping: the next expected message, and FAILED after any error.

    A suite's machine dispatches each message by its step number in ``_step`` (unframing it as
    the type that step expects); a message of another type, or with another step number, is
    the peer's error.
    """

    state: State
    step: int  # number of the next message of the run (the one this party receives next)

    def receive(self, data: bytes) -> bytes | None:
        """Consume the peer's next frame; return ours (None when nothing is to be sent)."""
        if self.state in (State.DONE, State.FAILED):
            raise LocalProtocolError(f"run already {self.state.value}")
        try:
            return self._step(data)
        except BaseException:
            # the peer's error (RemoteProtocolError), or ours -- a bug stays what it is
            self.state = State.FAILED
            raise

    def abort(self) -> None:
        """End the run here (peer gone, time limit): FAILED unless it already finished."""
        if self.state is not State.DONE:
            self.state = State.FAILED

    def _step(self, data: bytes) -> bytes | None:
        raise NotImplementedError


class AliceSide(Machine):
    """What every suite's Alice offers."""

    guard_bytes: int = 0  # of the run's bytes, those against a deviating Bob (after message 2)

    m: int  # padded size
    segments: int  # real size
    n: int | None = None  # Bob's padded size, once his first reply has told it
    peer_keys: bytes = b""  # Bob's public keys from his first reply (paper suite)
    _hits: list[bool]

    def start(self) -> bytes:
        raise NotImplementedError

    @property
    def hits(self) -> list[bool]:
        if self.state is not State.DONE:
            raise LocalProtocolError(f"no result in state {self.state.value}")
        return list(self._hits)


class BobSide(Machine):
    """What every suite's Bob offers; created from Alice's hello."""

    n: int
    guard_bytes: int = 0  # of his bytes, those that protect Alice against a deviating Bob

    def first_reply(self) -> bytes:
        raise NotImplementedError


PathSource = Sequence[Point] | Route | Callable[[Hello], Sequence[Point] | Route]


def bob_path(source: PathSource, hello: Hello, *, geographic: bool, limits: Limits) -> BobPath:
    """Bob's path on Alice's grid, cut to its box (:func:`protocol.geo.geometry.fit_to_box`), in
    the public size n: the padded size of his own path (at most ``max_segments``), whatever
    Alice's grid -- so neither a refusal nor the size tells her where his path lies -- or the
    size she asked for (``Hello.n``: the source cuts his path to it, and it is padded).  A
    :class:`~protocol.geo.volumes.Route` brings its bands (grid units) and windows (seconds after
    the hello's epoch) along."""
    raw = source(hello) if callable(source) else source
    route = as_route(raw)
    if geographic != (hello.grid.kind is GridKind.GEO):
        raise RemoteProtocolError("peer's grid kind does not match this path's coordinates")
    points = hello.grid.project_path(route.points, checked=False) if geographic else route.points
    if hello.n:
        n = limits.peer_size(hello.n)  # (a size outside 1..max_segments is refused)
        if route.segments > n:
            raise LocalProtocolError(f"{route.segments} segments where {n} were asked")
    else:
        n = limits.public_size(route.segments)
    return fit_to_box(points, hello.grid.range, n, route.bands, route.windows)
