"""The encrypted path-intersection protocol: Alice and Bob state machines (sans-IO).

Bob (key holder) and Alice each hold a polyline on the common grid.  Alice learns, for each of
her segments, whether it meets any of Bob's segments (closed segments, every degenerate case
as :func:`protocol.geometry.segments_intersect` says); Bob learns nothing.  Eight messages,
four round trips, whatever the path lengths:

====  =========  ==================================================================
 1    A -> B     HELLO: suites offered (+ Alice's zero-test key each), kappa, grid, m
 2    B -> A     KEYS: suite, n, Bob's keys, [X], [Y] per vertex, [dX], [dY], [K] per
                 segment, packed several values per Paillier plaintext
 3    A -> B     MASKED: every orientation / projection value v as a *linear form* in
                 Bob's ciphertexts (paper eq. for orient, see ``geometry``), masked
                 d = v + 2^l + r and packed
 4    B -> A     BITS: the l low bits of every d, encrypted (Veugen, step 2)
 5    A -> B     TESTS: for each value and each of its two thresholds (0 and 1 for an
                 orientation, 0 and T + 1 for a projection) Veugen's blinded tests:
                 one decomposition serves both, Alice shifts her mask r' = r + theta
 6    B -> A     GATES: Bob's shares of G, P, Z (and G_t, H) encrypted, with the eight
                 share products each segment pair needs
 7    A -> B     LEVEL1: s12, s34, col, w of every pair as fresh XOR shares (linear in
                 message 6), and Alice's new shares encrypted under *her* key
 8    B -> A     COUNTS: [rho_i * sum_k I_ik] under Alice's key, I = s12 s34 - col w
====  =========  ==================================================================

Alice zero-tests each count: her output bit.  Orientation values of a vertex against a segment
are computed once and shared by the two segments meeting at the vertex.  Both paths are padded
to a public size (next power of two by default) by repeating the last vertex, which changes no
answer.  Every ciphertext Alice receives is under Bob's key or is the final count under hers;
every value Bob decrypts is masked (statistically, kappa) or a uniform XOR share.  See
``docs/security.md`` for the argument.
"""

from __future__ import annotations

import enum
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .comparison import slot_bits, veugen_tests
from .dgk import DGKPrivateKey, DGKPublicKey
from .ecelgamal import ECPrivateKey, ECPublicKey
from .encoding import Reader
from .errors import InputRangeError, LocalProtocolError, ProtocolError, RemoteProtocolError
from .geometry import Point, orient_coefficients, projection_key, segment_terms
from .grid import GridKind, GridSpec
from .paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from .params import check_kappa
from .wire import Hello, KeysHeader, MsgType, Suite, frame, unframe
from .zerotest import ZeroTestPrivateKey, ZeroTestPublicKey

MAX_SEGMENTS = 256
MAX_MODULUS_BITS = 4096  # bounds the work a peer's key can impose
DGK_COUNT_BITS = 85  # DGK u = 263: holds comparison terms for l <= 86 and counts up to 256

AND = (0, 0, 0, 1)
NOR = (1, 0, 0, 0)
Table = tuple[int, int, int, int]


@dataclass(frozen=True, slots=True)
class Limits:
    """Public size policy.  ``max_segments`` bounds n and m (the probing attack needs many);
    ``pad_to_power_of_two`` hides a path's exact length inside its power-of-two bucket."""

    max_segments: int = MAX_SEGMENTS
    pad_to_power_of_two: bool = True

    def padded(self, segments: int) -> int:
        if not 1 <= segments <= self.max_segments:
            raise InputRangeError(f"{segments} segments outside 1..{self.max_segments}")
        if not self.pad_to_power_of_two:
            return segments
        return min(1 << (segments - 1).bit_length(), self.max_segments)


def pad_path(path: Sequence[Point], segments: int) -> tuple[Point, ...]:
    """Repeat the last vertex: zero-length segments at an existing vertex change no answer."""
    return tuple(path) + (path[-1],) * (segments + 1 - len(path))


def bilinear(table: Table, known1: int, known2: int) -> tuple[int, int, int, int]:
    """Coefficients (c, c1, c2, c12) with f(k1 ^ y1, k2 ^ y2) = c + c1 y1 + c2 y2 + c12 y1 y2.

    f is a two-input gate given by its truth table (f00, f01, f10, f11); the k are one party's
    shares, the y the other party's (encrypted) shares.  Same arithmetic for every input.
    """
    h00, h01, h10, h11 = (
        table[2 * (known1 ^ y1) + (known2 ^ y2)] for y1 in (0, 1) for y2 in (0, 1)
    )
    return h00, h10 - h00, h01 - h00, h11 - h10 - h01 + h00


class Kind(enum.IntEnum):
    O1 = 0  # orient(A_i, A_i+1, B_k): Alice segment i, Bob vertex k
    T = 1  # projection of Bob vertex k on Alice segment i
    O3 = 2  # orient(B_k, B_k+1, A_j): Bob segment k, Alice vertex j


@dataclass(frozen=True, slots=True)
class Piece:
    """One row chunk: Bob's vector chunk ``chunk`` combined for Alice's row ``row``."""

    kind: Kind
    row: int
    chunk: int
    length: int


class Layout:
    """Which value sits in which slot of which Paillier plaintext; public (m, n, slots)."""

    def __init__(self, m: int, n: int, per: int) -> None:
        self.m, self.n, self.per = m, n, per
        self.vertex_chunks = _chunks(n + 1, per)
        self.segment_chunks = _chunks(n, per)
        pieces = [
            Piece(kind, row, c, size)
            for kind, rows, chunks in (
                (Kind.O1, m, self.vertex_chunks),
                (Kind.T, m, self.vertex_chunks),
                (Kind.O3, m + 1, self.segment_chunks),
            )
            for row in range(rows)
            for c, size in enumerate(chunks)
        ]
        self.ciphertexts: list[list[Piece]] = []
        used = per
        for piece in pieces:
            if used + piece.length > per:
                self.ciphertexts.append([])
                used = 0
            self.ciphertexts[-1].append(piece)
            used += piece.length
        self.values: list[tuple[Kind, int, int]] = []
        for group in self.ciphertexts:
            for piece in group:
                self.values += [
                    (piece.kind, piece.row, piece.chunk * per + s) for s in range(piece.length)
                ]
        self.index = {value: position for position, value in enumerate(self.values)}
        # Bob's singles: (G, P, Z) per orientation value, (G_t, H) per projection value.
        self.single: dict[tuple[int, int], int] = {}
        for position, (kind, _, _) in enumerate(self.values):
            for which in (0, 1, 2) if kind is not Kind.T else (0, 1):
                self.single[(position, which)] = len(self.single)
        self.pairs = m * n

    @property
    def bob_vectors(self) -> int:
        return 2 * len(self.vertex_chunks) + 3 * len(self.segment_chunks)

    def pair_singles(self, i: int, k: int) -> list[int]:
        """Single indices [G1 P1 Z1 G2 P2 Z2 G3 P3 Z3 G4 P4 Z4 Gc Hc Gd Hd] of pair (i, k)."""
        v = self.index
        out: list[int] = []
        for key in ((Kind.O1, i, k), (Kind.O1, i, k + 1), (Kind.O3, i, k), (Kind.O3, i + 1, k)):
            out += [self.single[(v[key], w)] for w in (0, 1, 2)]
        for key in ((Kind.T, i, k), (Kind.T, i, k + 1)):
            out += [self.single[(v[key], w)] for w in (0, 1)]
        return out


def _chunks(count: int, per: int) -> list[int]:
    return [min(per, count - start) for start in range(0, count, per)]


# Per pair, the eight products Bob sends, as indices into pair_singles' list:
PRODUCTS = ((1, 4), (0, 3), (2, 5), (7, 10), (6, 9), (8, 11), (12, 14), (13, 15))


class State(enum.Enum):
    START = "start"
    WAIT_HELLO = "wait-hello"
    WAIT_KEYS = "wait-keys"
    WAIT_MASKED = "wait-masked"
    WAIT_BITS = "wait-bits"
    WAIT_TESTS = "wait-tests"
    WAIT_GATES = "wait-gates"
    WAIT_LEVEL1 = "wait-level1"
    WAIT_COUNTS = "wait-counts"
    DONE = "done"
    FAILED = "failed"


def generate_bits_key(suite: Suite) -> ZeroTestPrivateKey[Any]:
    """A fresh zero-test key for ``suite`` (once per drone; slow for DGK)."""
    if suite is Suite.COMPACT:
        return ECPrivateKey.generate()
    return DGKPrivateKey.generate(comparison_bits=DGK_COUNT_BITS)


def read_bits_key(
    suite: Suite, data: bytes, *, insecure_for_tests: bool = False
) -> ZeroTestPublicKey[Any]:
    if suite is Suite.COMPACT:
        return ECPublicKey.from_bytes(data)
    if len(data) > 3 * (MAX_MODULUS_BITS // 8) + 4:
        raise RemoteProtocolError("peer's DGK modulus is larger than 4096 bits")
    return DGKPublicKey.from_bytes(data, insecure_for_tests=insecure_for_tests)


@dataclass(frozen=True)
class BobKeys:
    paillier: PaillierPrivateKey
    bits: dict[Suite, ZeroTestPrivateKey[Any]]

    @classmethod
    def generate(cls, suites: Sequence[Suite] = (Suite.COMPACT,)) -> BobKeys:
        return cls(PaillierPrivateKey.generate(), {s: generate_bits_key(s) for s in suites})


class _Machine:
    """Shared bookkeeping: state checks, and FAILED after any error."""

    state: State

    def _expect(self, *states: State) -> None:
        if self.state not in states:
            raise LocalProtocolError(f"cannot receive in state {self.state.value}")

    def receive(self, data: bytes) -> bytes | None:
        """Consume the peer's next frame; return ours (None when the run is over)."""
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


# --------------------------------------------------------------------------- Alice


class Alice(_Machine):
    """The party without Bob's keys; learns one bit per segment of her path."""

    def __init__(
        self,
        path: Sequence[Point],
        grid: GridSpec,
        keys: dict[Suite, ZeroTestPrivateKey[Any]],
        *,
        kappa: int = 40,
        limits: Limits = Limits(),
        insecure_for_tests: bool = False,
    ) -> None:
        check_kappa(kappa, insecure_for_tests)
        if not keys:
            raise LocalProtocolError("offer at least one suite")
        if len(path) < 2:
            raise InputRangeError("a path needs at least two points")
        grid.check_points(path)
        self.segments = len(path) - 1
        self.m = limits.padded(self.segments)
        self.path = pad_path(path, self.m)
        self.grid, self.keys, self.kappa, self.limits = grid, dict(keys), kappa, limits
        self.insecure = insecure_for_tests
        self.l = grid.l
        self.state = State.START
        self._hits: list[bool] = []

    @property
    def hits(self) -> list[bool]:
        """For each of Alice's (unpadded) segments: does it meet Bob's path?"""
        if self.state is not State.DONE:
            raise LocalProtocolError(f"no result in state {self.state.value}")
        return list(self._hits)

    def start(self) -> bytes:
        """Message 1."""
        if self.state is not State.START:
            raise LocalProtocolError("already started")
        suites = tuple(self.keys)
        hello = Hello(
            suites,
            tuple(self.keys[s].public_key.to_bytes() for s in suites),
            self.kappa,
            self.grid,
            self.m,
        )
        self.state = State.WAIT_KEYS
        return hello.to_bytes()

    def _step(self, data: bytes) -> bytes | None:
        if self.state is State.WAIT_KEYS:
            return self._on_keys(data)
        if self.state is State.WAIT_BITS:
            return self._on_bits(data)
        if self.state is State.WAIT_GATES:
            return self._on_gates(data)
        self._expect(State.WAIT_COUNTS)
        self._on_counts(data)
        return None

    # message 2 -> 3
    def _on_keys(self, data: bytes) -> bytes:
        reader = Reader(unframe(data, MsgType.KEYS))
        head = KeysHeader.read(reader)
        if head.suite not in self.keys:
            raise RemoteProtocolError("peer chose a suite that was not offered")
        if not 1 <= head.n <= self.limits.max_segments:
            raise RemoteProtocolError(f"peer's path has {head.n} segments")
        self.suite, self.n = head.suite, head.n
        self.own = self.keys[head.suite]
        self.paillier = PaillierPublicKey.from_bytes(
            head.paillier_key, insecure_for_tests=self.insecure
        )
        if self.paillier.n.bit_length() > MAX_MODULUS_BITS:
            raise RemoteProtocolError("peer's Paillier modulus is larger than 4096 bits")
        self.bits = read_bits_key(head.suite, head.bits_key, insecure_for_tests=self.insecure)
        if 3 * self.l + 3 >= self.bits.plaintext_modulus:
            raise RemoteProtocolError("peer's zero-test plaintext space is too small")
        self.w = slot_bits(self.l, self.kappa)
        self.layout = Layout(self.m, self.n, max(1, (self.paillier.n.bit_length() - 1) // self.w))
        vectors = [self.paillier.read_ciphertext(reader) for _ in range(self.layout.bob_vectors)]
        reader.finish()
        nv, ns = len(self.layout.vertex_chunks), len(self.layout.segment_chunks)
        x, y = vectors[:nv], vectors[nv : 2 * nv]
        dx, dy, kk = (
            vectors[2 * nv : 2 * nv + ns],
            vectors[2 * nv + ns : 2 * nv + 2 * ns],
            vectors[2 * nv + 2 * ns :],
        )
        a = self.path
        orient_rows = [orient_coefficients(a[i], a[i + 1]) for i in range(self.m)]
        proj_rows = [projection_key(a[i], a[i + 1], self.grid.span) for i in range(self.m)]
        self._thresholds = {
            Kind.O1: [(0, 1)] * self.m,
            Kind.T: [(0, t + 1) for *_, t in proj_rows],
            Kind.O3: [(0, 1)] * (self.m + 1),
        }

        def piece_value(piece: Piece) -> tuple[PaillierCiphertext, int]:
            c = piece.chunk
            if piece.kind is Kind.O1:
                al, be, ga = orient_rows[piece.row]
                return x[c] * al + y[c] * be, ga
            if piece.kind is Kind.T:
                ex, ey, off, _ = proj_rows[piece.row]
                return x[c] * ex + y[c] * ey, off
            ax, ay = a[piece.row]
            return dx[c] * ay + dy[c] * (-ax) + kk[c], 0

        self._r = [secrets.randbits(self.l + self.kappa + 1) for _ in self.layout.values]
        masked: list[bytes] = []
        position = 0
        for group in self.layout.ciphertexts:
            parts = [piece_value(piece) for piece in group]
            acc = parts[-1][0]  # Horner: sum_j piece_j 2^(w offset_j), last piece first
            for piece, (value, _) in zip(group[-2::-1], parts[-2::-1], strict=True):
                acc = acc * (1 << (self.w * piece.length)) + value
            constants = [
                c for piece, (_, c) in zip(group, parts, strict=True) for _ in range(piece.length)
            ]
            plain = sum(
                (c + (1 << self.l) + self._r[position + slot]) << (self.w * slot)
                for slot, c in enumerate(constants)
            )
            position += len(constants)
            masked.append((acc + plain).rerandomize().to_bytes())
        self.state = State.WAIT_BITS
        return frame(MsgType.MASKED, b"".join(masked))

    # message 4 -> 5
    def _on_bits(self, data: bytes) -> bytes:
        reader = Reader(unframe(data, MsgType.BITS))
        count = len(self.layout.values)
        bits = self.bits.read_batch(reader, count * self.l)
        reader.finish()
        self._shares: list[tuple[int, int]] = []
        tokens: list[bytes] = []
        for position, (kind, row, _) in enumerate(self.layout.values):
            d = bits[position * self.l : (position + 1) * self.l]
            pair: list[int] = []
            for theta in self._thresholds[kind][row]:
                r = self._r[position] + theta
                delta = secrets.randbits(1)
                tokens += [self.bits.token(c) for c in veugen_tests(self.bits, d, r, delta, self.l)]
                pair.append(((r >> self.l) & 1) ^ delta)
            self._shares.append((pair[0], pair[1]))
        self.state = State.WAIT_GATES
        return frame(MsgType.TESTS, b"".join(tokens))

    def _alice_single(self, position: int, which: int) -> int:
        g, p = self._shares[position]
        return (g, p, g ^ p)[which]

    # message 6 -> 7
    def _on_gates(self, data: bytes) -> bytes:
        layout = self.layout
        reader = Reader(unframe(data, MsgType.GATES))
        batch = self.bits.read_batch(reader, len(layout.single) + 8 * layout.pairs)
        reader.finish()
        singles, products = batch[: len(layout.single)], batch[len(layout.single) :]
        inverse = {index: key for key, index in layout.single.items()}
        tokens: list[bytes] = []
        masks: list[int] = []
        for i in range(self.m):
            sel = int(self.path[i] != self.path[i + 1])
            for k in range(self.n):
                idx = layout.pair_singles(i, k)
                known = [self._alice_single(*inverse[j]) for j in idx]
                enc = [singles[j] for j in idx]
                prod = products[8 * (i * self.n + k) : 8 * (i * self.n + k) + 8]

                def gate(table: Table, which: int, weight: int) -> _Terms:
                    return _gate(table, which, weight, known, enc, prod)  # noqa: B023

                outputs: tuple[list[_Terms], ...] = (
                    [(1, []), gate(AND, 0, -1), gate(NOR, 1, -1)],  # s12
                    [(1, []), gate(AND, 3, -1), gate(NOR, 4, -1)],  # s34
                    [gate(AND, 2, sel), gate(AND, 5, 1 - sel)],  # col
                    [gate(NOR, 6, 1), gate(AND, 7, 1)],  # w
                )
                for terms in outputs:
                    mask = secrets.randbits(1)
                    sign = 1 - 2 * mask
                    total = self.bits.constant(mask + sign * sum(c for c, _ in terms))
                    for _, linear in terms:
                        for ct, coefficient in linear:
                            total = total + ct * (sign * coefficient)
                    tokens.append(self.bits.token(self.bits.rerandomize(total)))
                    masks.append(mask)
        self._level1 = masks
        monomials: list[int] = []
        for pair in range(layout.pairs):
            s12, s34, col, w = masks[4 * pair : 4 * pair + 4]
            monomials += [s12, s34, s12 * s34, col, w, col * w]
        encrypted = self.own.encrypt_batch(monomials)
        self.state = State.WAIT_COUNTS
        return frame(MsgType.LEVEL1, b"".join(tokens) + encrypted)

    # message 8
    def _on_counts(self, data: bytes) -> None:
        body = unframe(data, MsgType.COUNTS)
        size = self.own.public_key.token_size
        if len(body) != size * self.m:
            raise RemoteProtocolError("wrong number of counts")
        hits = [not self.own.token_is_zero(body[i * size : (i + 1) * size]) for i in range(self.m)]
        self._hits = hits[: self.segments]
        self.state = State.DONE


_Terms = tuple[int, list[tuple[Any, int]]]


def _gate(
    table: Table, which: int, weight: int, known: list[int], enc: list[Any], prod: list[Any]
) -> _Terms:
    """weight * f(x_p, x_q) for the pair's product ``which``: (constant, [(ct, coeff)])."""
    p, q = PRODUCTS[which]
    c, c1, c2, c12 = bilinear(table, known[p], known[q])
    return weight * c, [(enc[p], weight * c1), (enc[q], weight * c2), (prod[which], weight * c12)]


# --------------------------------------------------------------------------- Bob


class Bob(_Machine):
    """The key holder; learns nothing about Alice's path or the result."""

    def __init__(
        self,
        path: Sequence[Point] | Sequence[tuple[int, int]],
        keys: BobKeys,
        *,
        geographic: bool = False,
        limits: Limits = Limits(),
        insecure_for_tests: bool = False,
    ) -> None:
        if len(path) < 2:
            raise InputRangeError("a path needs at least two points")
        self.raw_path = tuple(path)
        self.geographic = geographic
        self.segments = len(path) - 1
        self.n = limits.padded(self.segments)
        self.keys, self.limits, self.insecure = keys, limits, insecure_for_tests
        self.state = State.WAIT_HELLO

    def _step(self, data: bytes) -> bytes | None:
        if self.state is State.WAIT_HELLO:
            return self._on_hello(data)
        if self.state is State.WAIT_MASKED:
            return self._on_masked(data)
        if self.state is State.WAIT_TESTS:
            return self._on_tests(data)
        self._expect(State.WAIT_LEVEL1)
        return self._on_level1(data)

    # message 1 -> 2
    def _on_hello(self, data: bytes) -> bytes:
        hello = Hello.from_bytes(data)
        try:
            check_kappa(hello.kappa, self.insecure)
        except LocalProtocolError as exc:
            raise RemoteProtocolError(f"peer's kappa refused: {exc}") from exc
        if not 1 <= hello.m <= self.limits.max_segments:
            raise RemoteProtocolError(f"peer's path has {hello.m} segments")
        chosen = [s for s in hello.suites if s in self.keys.bits]
        if not chosen:
            raise RemoteProtocolError("no common cipher suite")
        self.suite = chosen[0]
        self.grid, self.kappa, self.m, self.l = hello.grid, hello.kappa, hello.m, hello.grid.l
        self.alice_bits = read_bits_key(
            self.suite, hello.keys[hello.suites.index(self.suite)], insecure_for_tests=self.insecure
        )
        if self.alice_bits.plaintext_modulus <= self.n:
            raise RemoteProtocolError("peer's zero-test plaintext space cannot hold the counts")
        self.bits = self.keys.bits[self.suite]
        if self.geographic != (self.grid.kind is GridKind.GEO):
            raise RemoteProtocolError("peer's grid kind does not match this path's coordinates")
        try:
            path = self.grid.project_path(self.raw_path) if self.geographic else self.raw_path
            self.grid.check_points(path)
        except InputRangeError as exc:
            raise RemoteProtocolError(f"this path does not fit the peer's grid: {exc}") from exc
        self.path = pad_path(path, self.n)
        paillier = self.keys.paillier.public_key
        self.w = slot_bits(self.l, self.kappa)
        self.layout = Layout(self.m, self.n, max(1, (paillier.n.bit_length() - 1) // self.w))
        b = self.path
        terms = [segment_terms(b[k], b[k + 1]) for k in range(self.n)]
        vectors = (
            [p[0] for p in b],
            [p[1] for p in b],
            [t[0] for t in terms],
            [t[1] for t in terms],
            [t[2] for t in terms],
        )
        cts: list[bytes] = []
        for vector in vectors:
            for start in range(0, len(vector), self.layout.per):
                chunk = vector[start : start + self.layout.per]
                packed = sum(v << (self.w * s) for s, v in enumerate(chunk))
                cts.append(paillier.encrypt(packed).to_bytes())
        head = KeysHeader(self.suite, self.n, paillier.to_bytes(), self.bits.public_key.to_bytes())
        self.state = State.WAIT_MASKED
        return frame(MsgType.KEYS, head.to_bytes() + b"".join(cts))

    # message 3 -> 4
    def _on_masked(self, data: bytes) -> bytes:
        reader = Reader(unframe(data, MsgType.MASKED))
        paillier = self.keys.paillier
        values: list[int] = []
        for group in self.layout.ciphertexts:
            slots = sum(p.length for p in group)
            packed = paillier.decrypt(paillier.public_key.read_ciphertext(reader))
            if packed >> (self.w * slots):
                raise RemoteProtocolError("masked value out of range")
            values += [(packed >> (self.w * s)) & ((1 << self.w) - 1) for s in range(slots)]
        reader.finish()
        self._high = [(d >> self.l) & 1 for d in values]
        low = [(d >> i) & 1 for d in values for i in range(self.l)]
        self.state = State.WAIT_TESTS
        return frame(MsgType.BITS, self.bits.encrypt_batch(low))

    # message 5 -> 6
    def _on_tests(self, data: bytes) -> bytes:
        body = unframe(data, MsgType.TESTS)
        size = self.bits.public_key.token_size
        group = self.l + 1
        count = len(self.layout.values)
        if len(body) != 2 * count * group * size:
            raise RemoteProtocolError("wrong number of comparison tests")
        self._shares: list[tuple[int, int]] = []
        for position in range(count):
            pair: list[int] = []
            for t in range(2):
                start = (2 * position + t) * group * size
                zeros = sum(
                    self.bits.token_is_zero(body[start + j * size : start + (j + 1) * size])
                    for j in range(group)
                )
                if zeros > 1:
                    raise RemoteProtocolError("more than one zero in a comparison")
                pair.append(self._high[position] ^ zeros)
            self._shares.append((pair[0], pair[1]))
        layout = self.layout
        singles = [0] * len(layout.single)
        for (position, which), index in layout.single.items():
            g, p = self._shares[position]
            singles[index] = (g, p, g ^ p)[which]
        products: list[int] = []
        for i in range(self.m):
            for k in range(self.n):
                idx = layout.pair_singles(i, k)
                products += [singles[idx[p]] * singles[idx[q]] for p, q in PRODUCTS]
        self.state = State.WAIT_LEVEL1
        return frame(MsgType.GATES, self.bits.encrypt_batch(singles + products))

    # message 7 -> 8
    def _on_level1(self, data: bytes) -> bytes:
        reader = Reader(unframe(data, MsgType.LEVEL1))
        size = self.bits.public_key.token_size
        pairs = self.layout.pairs
        shares = [0 if self.bits.token_is_zero(reader.take(size)) else 1 for _ in range(4 * pairs)]
        monomials = self.alice_bits.read_batch(reader, 6 * pairs)
        reader.finish()
        tokens: list[bytes] = []
        for i in range(self.m):
            total = self.alice_bits.constant(0)
            for k in range(self.n):
                pair = i * self.n + k
                s12, s34, col, w = shares[4 * pair : 4 * pair + 4]
                enc = monomials[6 * pair : 6 * pair + 6]
                for sign, (b1, b2), (e1, e2, e12) in (
                    (1, (s12, s34), enc[0:3]),
                    (-1, (col, w), enc[3:6]),
                ):
                    c, c1, c2, c12 = bilinear(AND, b1, b2)
                    total = (
                        total + sign * c + e1 * (sign * c1) + e2 * (sign * c2) + e12 * (sign * c12)
                    )
            tokens.append(self.alice_bits.token(self.alice_bits.blind(total)))
        self.state = State.DONE
        return frame(MsgType.COUNTS, b"".join(tokens))
