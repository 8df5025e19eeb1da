"""The encrypted path-intersection protocol: what both suites share, and the entry points.

Bob and Alice each hold a polyline on the common grid.  Alice learns, for each of her
segments, whether it meets any of Bob's segments (closed segments, every degenerate case as
:func:`protocol.geo.geometry.segments_intersect` says); Bob learns nothing.  Both suites compute the
same thing in the same three stages, each a sans-IO sub-protocol:

1. *Values.*  Every orientation and projection value v of the circuit (paper section IV-B) is
   a sum of products of one party's coordinates with the other's (:mod:`protocol.geo.geometry`):
   ``O1`` orient(A_i, A_i+1, B_k), ``T`` where B_k projects on Alice's segment i, ``O3``
   orient(B_k, B_k+1, A_j).  Compact: additive shares from OT products
   (:mod:`protocol.compact.products`); paper: Paillier linear forms, statistically masked.
2. *Comparisons.*  XOR shares of the sign bits of every v.  Compact: radix-2^w millionaires on
   OTs (:mod:`protocol.compact.millionaire`); paper: Veugen's DGK comparison
   (:mod:`protocol.paper.comparison`).
3. *Circuit.*  :mod:`protocol.circuits.paths` on those shares, then Bob sends his shares of Alice's
   m output bits.  Compact: Beaver triples from OTs (:mod:`protocol.compact.gmw`); paper:
   homomorphic gates (:mod:`protocol.paper.hegates`).

The suites live in :mod:`protocol.compact.suite` and :mod:`protocol.paper.suite`, what they
share (limits, layout, state handling) in :mod:`protocol.run`; this module holds the
:class:`Alice` and :class:`Bob` entry points.  ``docs/security.md`` argues what each message
shows its receiver.
"""

from __future__ import annotations

from collections.abc import MutableMapping, Sequence

from protocol.compact.suite import CompactAlice, CompactBob
from protocol.errors import InputRangeError, LocalProtocolError, RemoteProtocolError
from protocol.geo.geometry import Point
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import CROSSING, NO_SEPARATION, Route, Separation, VolumeSpec, as_route
from protocol.messages import Hello, Suite
from protocol.ot.setup import DEFAULT_BLOCK_BITS, DEFAULT_SECURITY, ChooserSetup, HolderSetup
from protocol.paper.keys import BobKeys
from protocol.paper.suite import PaperAlice, PaperBob
from protocol.run import DEFAULT_LIMITS, AliceSide, BobSide, Limits, PathSource, State, bob_path


class Alice:
    """The party without keys: learns one bit per segment of her path.

    ``setup`` is the OT setup cached with this peer (compact suite), or None for a fresh one;
    after the run :attr:`setup` holds the setup to cache.  ``ask_n`` asks Bob for exactly
    that many segments of his path (``Hello.n``; his answer of another size is refused).

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
        limits: Limits = DEFAULT_LIMITS,
        horizon_m: int = 0,
        ask_n: int = 0,
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
            self._impl = CompactAlice(
                route,
                grid,
                setup=setup,
                limits=limits,
                horizon_m=horizon_m,
                ask_n=ask_n,
                volumes=volumes,
                digit_bits=digit_bits,
                block_bits=block_bits,
                ot_security=ot_security,
            )
        else:
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
                ask_n=ask_n,
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
    :class:`~protocol.geo.volumes.Route`, or a function of Alice's hello (to cut it at her
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
        limits: Limits = DEFAULT_LIMITS,
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
        except BaseException:
            self._state = State.FAILED
            raise

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
            return CompactBob(hello, path, self.setups, self.separation)

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
