"""The encrypted path-intersection protocol: what both suites share, and the entry points.

Bob and Alice each hold a polyline on the common grid.  Alice learns, for each of her
segments, whether it meets any of Bob's segments (closed segments, every degenerate case as
:func:`protocol.geometry.segments_intersect` says); Bob learns nothing.  Both suites compute the
same thing in the same three stages, each a sans-IO sub-protocol:

1. *Values.*  Every orientation and projection value v of the circuit (paper section IV-B) is
   a sum of products of one party's coordinates with the other's (:mod:`protocol.geometry`):
   ``O1`` orient(A_i, A_i+1, B_k), ``T`` where B_k projects on Alice's segment i, ``O3``
   orient(B_k, B_k+1, A_j).  Compact: additive shares from OT products
   (:mod:`protocol.products`); paper: Paillier linear forms, statistically masked.
2. *Comparisons.*  XOR shares of the sign bits of every v.  Compact: radix-2^w millionaires on
   OTs (:mod:`protocol.millionaire`); paper: Veugen's DGK comparison (:mod:`protocol.comparison`).
3. *Circuit.*  :mod:`protocol.pathcircuit` on those shares, then Bob sends his shares of Alice's
   m output bits.  Compact: Beaver triples from OTs (:mod:`protocol.gmw`); paper: homomorphic
   gates (:mod:`protocol.hegates`).

The suites live in :mod:`protocol.suite_compact` and :mod:`protocol.suite_paper`; this module
holds the public layout of a run, the common state handling and the :class:`Alice` and
:class:`Bob` entry points.  Both paths are padded to a public size (next power of two by
default) by repeating the last vertex, which changes no answer.  ``docs/security.md`` argues
what each message shows its receiver.
"""

from __future__ import annotations

import enum
import functools
from collections.abc import Callable, MutableMapping, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from .circuit import Circuit
from .dgk import DGKPrivateKey
from .errors import InputRangeError, LocalProtocolError, ProtocolError, RemoteProtocolError
from .geometry import BobPath, Point, fit_to_box
from .grid import GridKind, GridSpec
from .ot.setup import DEFAULT_BLOCK_BITS, DEFAULT_SECURITY, ChooserSetup, HolderSetup
from .paillier import PaillierPrivateKey
from .pathcircuit import Capsules, Orient, Proj, Range, volume_hits
from .volumes import (
    CROSSING,
    MAX_SEPARATION,
    NO_SEPARATION,
    Route,
    Separation,
    VolumeSpec,
    as_route,
)
from .wire import Hello, Suite, put_blob

W = TypeVar("W")

MAX_SEGMENTS = 256
MAX_MODULUS_BITS = 4096  # bounds the work a peer's key can impose
DGK_BITS = 85  # the paper suite's DGK u = 263 holds comparison terms for l <= 86


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

    def peer_size(self, segments: int) -> int:
        """The size the peer announces for its path, refused outside 1..max_segments."""
        if not 1 <= segments <= self.max_segments:
            raise RemoteProtocolError(f"peer's path has {segments} segments")
        return segments


class Kind(enum.IntEnum):
    """The linear forms a run computes (:mod:`protocol.geometry`, :mod:`protocol.volumes`)."""

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
        """Add the conflict circuit (:func:`protocol.pathcircuit.volume_hits`) on the per-form
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

    A suite's machine lists its handlers in ``HANDLERS`` (message type -> method); a message of
    another type, or with another step number, is the peer's error.
    """

    state: State
    step: int  # number of the next message of the run (the one this party receives next)

    def receive(self, data: bytes) -> bytes | None:
        """Consume the peer's next frame; return ours (None when nothing is to be sent)."""
        if self.state in (State.DONE, State.FAILED):
            raise LocalProtocolError(f"run already {self.state.value}")
        try:
            return self._step(data)
        except ProtocolError:
            self.state = State.FAILED
            raise
        except (ValueError, ArithmeticError, IndexError) as exc:
            self.state = State.FAILED
            raise RemoteProtocolError(f"malformed message: {exc}") from exc

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


@dataclass(frozen=True)
class BobKeys:
    """Bob's long-term keys for the paper suite (the compact suite needs none)."""

    paillier: PaillierPrivateKey
    dgk: DGKPrivateKey

    @classmethod
    def generate(cls) -> BobKeys:
        return cls(PaillierPrivateKey.generate(), DGKPrivateKey.generate(comparison_bits=DGK_BITS))

    def public_bytes(self) -> bytes:
        """The public keys as the KEYS message carries them (what a beacon's keys hash
        covers): the Paillier and the DGK public key, each a 2-byte length and its bytes."""
        return put_blob(self.paillier.public_key.to_bytes()) + put_blob(
            self.dgk.public_key.to_bytes()
        )

    @functools.cached_property
    def paillier_proof(self) -> bytes:
        """The proof that the Paillier modulus is fit (:mod:`protocol.keyproof`), made once."""
        from .keyproof import prove

        return prove(self.paillier)


PathSource = Sequence[Point] | Route | Callable[[Hello], Sequence[Point] | Route]


def bob_path(source: PathSource, hello: Hello, *, geographic: bool, limits: Limits) -> BobPath:
    """Bob's path on Alice's grid, cut to its box (:func:`protocol.geometry.fit_to_box`), in
    the public size n: the padded size of his own path (at most ``max_segments``), whatever
    Alice's grid -- so neither a refusal nor the size tells her where his path lies.  A
    :class:`~protocol.volumes.Route` brings its bands (grid units) and windows (seconds after
    the hello's epoch) along."""
    raw = source(hello) if callable(source) else source
    route = as_route(raw)
    if geographic != (hello.grid.kind is GridKind.GEO):
        raise RemoteProtocolError("peer's grid kind does not match this path's coordinates")
    points = hello.grid.project_path(route.points, checked=False) if geographic else route.points
    n = limits.padded(min(route.segments, limits.max_segments))
    return fit_to_box(points, hello.grid.range, n, route.bands, route.windows)


class Alice:
    """The party without keys: learns one bit per segment of her path.

    ``setup`` is the OT setup cached with this peer (compact suite), or None for a fresh one;
    after the run :attr:`setup` holds the setup to cache.

    ``trusted_keys`` (paper suite only): the caller vouches for Bob's keys and software.  Alice
    cannot check the range of Bob's Paillier plaintexts (out-of-range values put her
    coefficients above the masked slots, where Bob reads them) nor his DGK key (a generator of
    smooth order opens her blinded tests), so the paper suite refuses to start without it
    (docs/security.md, D2 and D3).  The compact suite needs no such trust.
    """

    def __init__(
        self,
        path: Sequence[Point] | Route,
        grid: GridSpec,
        *,
        suite: Suite = Suite.COMPACT,
        setup: HolderSetup | None = None,
        kappa: int = 40,
        limits: Limits = Limits(),
        horizon_m: int = 0,
        volumes: VolumeSpec = CROSSING,
        digit_bits: int | None = None,
        block_bits: int = DEFAULT_BLOCK_BITS,
        ot_security: int = DEFAULT_SECURITY,
        trusted_keys: bool = False,
        insecure_for_tests: bool = False,
    ) -> None:
        if not isinstance(path, Route) and len(path) < 2:
            raise InputRangeError("a path needs at least two points")
        route = as_route(path)
        grid.check_points(route.points)
        if (route.bands is not None and not volumes.bands) or (
            route.windows is not None and not volumes.windows
        ):
            raise InputRangeError("bands and windows need an altitude and a time range")
        self.suite = suite
        self._impl: AliceSide
        if suite is Suite.COMPACT:
            from .suite_compact import CompactAlice

            self._impl = CompactAlice(
                route,
                grid,
                setup=setup,
                limits=limits,
                horizon_m=horizon_m,
                volumes=volumes,
                digit_bits=digit_bits,
                block_bits=block_bits,
                ot_security=ot_security,
            )
        else:
            from .suite_paper import PaperAlice

            if volumes != CROSSING:
                raise InputRangeError(
                    "the paper suite computes the paper's predicate (the crossing) only: "
                    "separation, altitudes and times need the compact suite"
                )
            self._impl = PaperAlice(
                route.points,
                grid,
                kappa=kappa,
                limits=limits,
                horizon_m=horizon_m,
                trusted_keys=trusted_keys,
                insecure_for_tests=insecure_for_tests,
            )

    @property
    def state(self) -> State:
        return self._impl.state

    @property
    def hits(self) -> list[bool]:
        """For each of Alice's (unpadded) segments: does it meet Bob's path?"""
        return self._impl.hits

    @property
    def setup(self) -> HolderSetup | None:
        """The compact suite's OT setup with this peer (cache it for the next run)."""
        found = getattr(self._impl, "setup", None)
        return found if isinstance(found, HolderSetup) else None

    @property
    def m(self) -> int:
        return self._impl.m

    @property
    def n(self) -> int | None:
        """Bob's padded segment count (public, as ``m``), None until his first reply."""
        return self._impl.n

    @property
    def guard_bytes(self) -> int:
        """How many of the run's bytes protect Alice against a deviating Bob: the OT
        consistency check (compact suite), Bob's Paillier key proof (paper suite).  Known
        once Bob's first reply arrived."""
        return self._impl.guard_bytes

    @property
    def peer_keys(self) -> bytes:
        """Bob's public keys as his first reply carried them (:meth:`BobKeys.public_bytes`;
        empty for the compact suite, which has none): for checking against his beacon."""
        return self._impl.peer_keys

    def start(self) -> bytes:
        return self._impl.start()

    def receive(self, data: bytes) -> bytes | None:
        return self._impl.receive(data)

    def abort(self) -> None:
        self._impl.abort()


class Bob:
    """The answering party: learns nothing about Alice's path or the result.

    ``path`` is his polyline (grid points, or WGS84 degE7 with ``geographic``) or
    :class:`~protocol.volumes.Route`, or a function of Alice's hello (to cut it at her
    horizon, to put his windows on her epoch).  ``setups`` keeps compact-suite OT setups by
    id (the caller keeps one mapping per peer); ``keys`` are needed for the paper suite only.
    ``separation``: Bob's own minima; a compact run uses the larger of his and Alice's (the
    paper suite computes the crossing only and refuses volumes).
    """

    def __init__(
        self,
        path: PathSource,
        *,
        keys: BobKeys | None = None,
        setups: MutableMapping[bytes, ChooserSetup] | None = None,
        suites: Sequence[Suite] = (Suite.COMPACT, Suite.PAPER),
        geographic: bool = False,
        limits: Limits = Limits(),
        separation: Separation = NO_SEPARATION,
        insecure_for_tests: bool = False,
    ) -> None:
        self.source, self.keys, self.geographic = path, keys, geographic
        self.separation = separation
        self.setups: MutableMapping[bytes, ChooserSetup] = {} if setups is None else setups
        self.suites = tuple(suites)
        self.limits, self.insecure = limits, insecure_for_tests
        self._impl: BobSide | None = None
        self._state = State.START

    @property
    def state(self) -> State:
        return self._impl.state if self._impl is not None else self._state

    @property
    def n(self) -> int:
        if self._impl is None:
            raise LocalProtocolError("n is known after the hello")
        return self._impl.n

    @property
    def guard_bytes(self) -> int:
        """How many of Bob's bytes protect Alice against a deviating Bob (as
        :attr:`Alice.guard_bytes`); 0 before the hello."""
        return 0 if self._impl is None else self._impl.guard_bytes

    def receive(self, data: bytes) -> bytes | None:
        if self._impl is not None:
            return self._impl.receive(data)
        if self._state is not State.START:
            raise LocalProtocolError(f"run already {self._state.value}")
        try:
            self._impl = self._create(Hello.from_bytes(data))
            return self._impl.first_reply()
        except ProtocolError:
            self._state = State.FAILED
            raise
        except (ValueError, ArithmeticError, IndexError) as exc:
            self._state = State.FAILED
            raise RemoteProtocolError(f"malformed hello: {exc}") from exc

    def _create(self, hello: Hello) -> BobSide:
        if hello.suite not in self.suites:
            raise RemoteProtocolError(f"suite {hello.suite.label} is not offered here")
        if not 1 <= hello.m <= self.limits.max_segments:
            raise RemoteProtocolError(f"peer's path has {hello.m} segments")
        try:
            path = bob_path(self.source, hello, geographic=self.geographic, limits=self.limits)
        except InputRangeError as exc:  # Bob's own input (fewer than two points, bad degE7)
            raise LocalProtocolError(f"this path cannot be compared: {exc}") from exc
        if hello.suite is Suite.COMPACT:
            from .suite_compact import CompactBob

            return CompactBob(hello, path, self.setups, self.separation)
        from .suite_paper import PaperBob

        if hello.volumes != CROSSING:
            raise RemoteProtocolError("the paper suite compares no volumes")
        if self.keys is None:
            raise LocalProtocolError("the paper suite needs Bob's keys")
        return PaperBob(hello, path, self.keys, insecure=self.insecure)

    def abort(self) -> None:
        if self._impl is not None:
            self._impl.abort()
        elif self._state is not State.DONE:
            self._state = State.FAILED
