"""The paper suite: the path protocol on Paillier and DGK (the paper's design, at 112 bits).

Messages (step numbers in the frame header), D = AND levels of the circuit:

=======  =========  ==================================================================
 1       A -> B     HELLO: grid, m, kappa, horizon
 2       B -> A     KEYS: n, Bob's Paillier and DGK keys, [X], [Y] per vertex, [dX], [dY],
                    [K] per segment, packed several values per Paillier plaintext
 3       A -> B     MASKED: every orientation / projection value v as a *linear form* in
                    Bob's ciphertexts, masked and packed (:class:`~.comparison.ComparisonAlice`)
 4       B -> A     BITS: the l low bits of every masked value, DGK-encrypted
 5       A -> B     TESTS: Veugen's tests for two thresholds per value (0 and 1 for an
                    orientation, 0 and T + 1 for a projection), one decomposition for both
 6, 8..  B -> A     GATES_IN: one AND level of the path circuit (:mod:`.hegates`)
 7, 9..  A -> B     GATES_OUT
 6 + 2D  B -> A     OPEN: Bob's shares of Alice's m result bits
=======  =========  ==================================================================

The orientation values of a vertex against a segment are computed once and shared by the two
segments meeting at the vertex; Bob's vectors are packed so that one Paillier scalar
multiplication serves a whole chunk of them (SIMD).
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from dataclasses import dataclass

from protocol.circuits.boolean import Circuit
from protocol.circuits.paths import Orient, Proj
from protocol.errors import LocalProtocolError, RemoteProtocolError, UntrustedKeysError
from protocol.geo.geometry import BobPath, Point, orient_coefficients, pad_path, projection_key
from protocol.geo.grid import GridSpec
from protocol.messages import (
    NONCE_SIZE,
    Hello,
    MsgType,
    Suite,
    frame,
    put_blob,
    take_blob,
    unframe,
)
from protocol.paper import keyproof
from protocol.paper.comparison import (
    BitDecompositions,
    BlindedTests,
    ComparisonAlice,
    ComparisonBob,
    MaskedDifferences,
    PackedValues,
    slot_bits,
)
from protocol.paper.hegates import HeGatesAlice, HeGatesBob
from protocol.paper.keys import MAX_MODULUS_BITS, BobKeys
from protocol.primitives.dgk import DGKPublicKey
from protocol.primitives.paillier import PaillierCiphertext, PaillierPublicKey
from protocol.primitives.params import check_kappa
from protocol.run import AliceSide, BobSide, Kind, Layout, Limits, State, Wires, check_ask
from protocol.wire.encoding import Reader

MAX_KEY_BYTES = 3 * (MAX_MODULUS_BITS // 8) + 4


@dataclass(frozen=True, slots=True)
class Piece:
    """One row chunk: Bob's vector chunk ``chunk`` combined for Alice's row ``row``."""

    kind: Kind
    row: int
    chunk: int
    length: int


class Packing:
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
        self.values = [
            (piece.kind, piece.row, piece.chunk * per + s)
            for group in self.ciphertexts
            for piece in group
            for s in range(piece.length)
        ]

    @property
    def bob_vectors(self) -> int:
        return 2 * len(self.vertex_chunks) + 3 * len(self.segment_chunks)

    @property
    def slots(self) -> list[int]:
        return [sum(p.length for p in group) for group in self.ciphertexts]


def _chunks(count: int, per: int) -> list[int]:
    return [min(per, count - start) for start in range(0, count, per)]


def make_circuit(layout: Layout, packing: Packing) -> tuple[Circuit, list[int]]:
    """The path circuit on two comparison shares per value (packing order), and the input
    order: the circuit's input k is threshold k % 2 of packing value k // 2."""
    circuit = Circuit()
    wires = [Wires()] * len(layout.values)
    for kind, row, col in packing.values:
        ge0, ge1 = circuit.input(), circuit.input()
        position = layout.position(kind, row, col)
        if kind is Kind.T:
            wires[position] = Wires(proj=Proj(circuit.not_(ge0), ge1))
        else:  # ge0 = [o >= 0], ge1 = [o >= 1]
            wires[position] = Wires(orient=Orient(ge1, circuit.xor(ge0, ge1)))
    layout.outputs(circuit, wires)
    return circuit, [2] * len(packing.values)


def read_dgk_key(data: bytes, insecure: bool) -> DGKPublicKey:
    if len(data) > MAX_KEY_BYTES:
        raise RemoteProtocolError("peer's DGK modulus is larger than 4096 bits")
    return DGKPublicKey.from_bytes(data, insecure_for_tests=insecure)


# --------------------------------------------------------------------------- Alice


class PaperAlice(AliceSide):
    def __init__(
        self,
        path: Sequence[Point],
        grid: GridSpec,
        *,
        kappa: int,
        limits: Limits,
        horizon_m: int = 0,
        ask_n: int = 0,
        trusted_keys: bool = False,
        insecure_for_tests: bool = False,
    ) -> None:
        self.ask_n = check_ask(ask_n, limits)
        if not trusted_keys:  # D3 (docs/security.md): nothing of Alice's without the trust
            raise UntrustedKeysError(
                "the paper suite runs only with a peer trusted with its keys (trusted_keys=True):"
                " Alice cannot check the range of Bob's ciphertexts nor his DGK key"
            )
        check_kappa(kappa, insecure_for_tests)
        self.segments = len(path) - 1
        self.m = limits.padded(self.segments)
        self.path = pad_path(path, self.m)
        self.grid, self.kappa, self.limits, self.horizon_m = grid, kappa, limits, horizon_m
        self.insecure = insecure_for_tests
        self.l = grid.l
        self.state = State.START
        self.step = 2
        self._hits: list[bool] = []

    def start(self) -> bytes:
        if self.state is not State.START:
            raise LocalProtocolError("already started")
        self.state = State.RUNNING
        hello = Hello(
            Suite.PAPER,
            self.kappa,
            self.grid,
            self.m,
            self.horizon_m,
            secrets.token_bytes(NONCE_SIZE),
            n=self.ask_n,
        )
        return hello.to_bytes()

    def _step(self, data: bytes) -> bytes | None:
        if self.state is not State.RUNNING:
            raise LocalProtocolError(f"cannot receive in state {self.state.value}")
        step = self.step
        if step == 2:
            reply = self._on_keys(unframe(data, MsgType.KEYS, 2))
        elif step == 4:
            reply = self._on_bits(unframe(data, MsgType.BITS, 4))
        elif step == 6 + 2 * self.gates.depth:
            self._on_open(unframe(data, MsgType.OPEN, step))
            return None
        else:
            reply = frame(
                MsgType.GATES_OUT,
                step + 1,
                self.gates.evaluate(unframe(data, MsgType.GATES_IN, step)),
            )
        self.step += 2
        return reply

    # message 2 -> 3
    def _on_keys(self, body: bytes) -> bytes:
        reader = Reader(body)
        self.n = self.limits.peer_size(reader.uint(2), self.ask_n)
        self._read_keys(reader, body)
        self.w = slot_bits(self.l, self.kappa)
        per = max(1, (self.paillier.n.bit_length() - 1) // self.w)
        self.layout = Layout(self.m, self.n)
        self.packing = packing = Packing(self.m, self.n, per)
        vectors = [self.paillier.read_ciphertext(reader) for _ in range(packing.bob_vectors)]
        reader.finish()
        packed, thresholds = self._pack_forms(vectors)
        self.comparison = ComparisonAlice(
            self.paillier,
            self.dgk,
            self.l,
            self.kappa,
            packed,
            thresholds,
            insecure_for_tests=self.insecure,
        )
        self.circuit, _ = make_circuit(self.layout, packing)
        return frame(MsgType.MASKED, 3, self.comparison.mask().to_bytes())

    def _read_keys(self, reader: Reader, body: bytes) -> None:
        """Bob's Paillier and DGK keys, checked, and the proof on his Paillier key."""
        start = reader.offset
        paillier_key = take_blob(reader)
        if len(paillier_key) > MAX_MODULUS_BITS // 8:
            raise RemoteProtocolError("peer's Paillier modulus is larger than 4096 bits")
        self.paillier = PaillierPublicKey.from_bytes(paillier_key, insecure_for_tests=self.insecure)
        self.dgk = read_dgk_key(take_blob(reader), self.insecure)
        self.peer_keys = body[start : reader.offset]  # as BobKeys.public_bytes() wrote them
        proof = take_blob(reader)
        keyproof.verify(self.paillier, proof)  # before any of Bob's ciphertexts
        self.guard_bytes = 2 + len(proof)
        if 3 * self.l + 3 >= self.dgk.plaintext_modulus:
            raise RemoteProtocolError("peer's DGK plaintext space is too small")

    def _pack_forms(
        self, vectors: list[PaillierCiphertext]
    ) -> tuple[list[PackedValues], list[list[int]]]:
        """Every value as a linear form in Bob's vectors, packed per Paillier plaintext, and
        its two thresholds."""
        packing = self.packing
        nv, ns = len(packing.vertex_chunks), len(packing.segment_chunks)
        x, y = vectors[:nv], vectors[nv : 2 * nv]
        dx, dy, kk = (
            vectors[2 * nv : 2 * nv + ns],
            vectors[2 * nv + ns : 2 * nv + 2 * ns],
            vectors[2 * nv + 2 * ns :],
        )
        a = self.path
        orient_rows = [orient_coefficients(a[i], a[i + 1]) for i in range(self.m)]
        proj_rows = [projection_key(a[i], a[i + 1], self.grid.span) for i in range(self.m)]

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

        packed: list[PackedValues] = []
        for group in packing.ciphertexts:
            parts = [piece_value(piece) for piece in group]
            acc = parts[-1][0]  # Horner: sum_j piece_j 2^(w offset_j), last piece first
            for piece, (value, _) in zip(group[-2::-1], parts[-2::-1], strict=True):
                acc = acc * (1 << (self.w * piece.length)) + value
            constants = tuple(
                c for piece, (_, c) in zip(group, parts, strict=True) for _ in range(piece.length)
            )
            packed.append(PackedValues(acc, constants))
        thresholds = [
            [0, proj_rows[row][3] + 1] if kind is Kind.T else [0, 1]
            for kind, row, _ in packing.values
        ]
        return packed, thresholds

    # message 4 -> 5
    def _on_bits(self, body: bytes) -> bytes:
        if len(body) != self.comparison.bits_size():
            raise RemoteProtocolError("wrong number of bit ciphertexts")
        tests = self.comparison.compare_bits(BitDecompositions(body))
        inputs = [s for per in self.comparison.shares for s in per]
        inputs.append(0)  # Alice's share of Bob's flag (Layout.outputs)
        self.gates = HeGatesAlice(self.circuit, self.dgk, inputs)
        return frame(MsgType.TESTS, 5, tests.to_bytes())

    def _on_open(self, body: bytes) -> None:
        self._hits = [bool(b) for b in self.gates.open(body)[: self.segments]]
        self.state = State.DONE


# --------------------------------------------------------------------------- Bob


class PaperBob(BobSide):
    def __init__(self, hello: Hello, path: BobPath, keys: BobKeys, *, insecure: bool) -> None:
        n = path.segments
        try:
            check_kappa(hello.kappa, insecure)
        except LocalProtocolError as exc:
            raise RemoteProtocolError(f"peer's kappa refused: {exc}") from exc
        if hello.offer:
            raise RemoteProtocolError("the paper suite takes no offer")
        self.paillier, self.dgk = keys.paillier, keys.dgk
        self.grid, self.kappa, self.m, self.n = hello.grid, hello.kappa, hello.m, n
        self.l = self.grid.l
        if 3 * self.l + 3 >= self.dgk.public_key.plaintext_modulus:
            raise LocalProtocolError(f"this DGK key cannot compare {self.l}-bit values")
        self.path = path
        pub = self.paillier.public_key
        self.w = slot_bits(self.l, self.kappa)
        per = max(1, (pub.n.bit_length() - 1) // self.w)
        self.layout = Layout(self.m, n)
        self.packing = packing = Packing(self.m, n, per)
        self.circuit, counts = make_circuit(self.layout, packing)
        self.comparison = ComparisonBob(
            self.paillier,
            self.dgk,
            self.l,
            self.kappa,
            packing.slots,
            counts,
            insecure_for_tests=insecure,
        )
        terms = [path.line(k) for k in range(n)]
        vectors = (
            [p[0] for p in path.points],
            [p[1] for p in path.points],
            [t[0] for t in terms],
            [t[1] for t in terms],
            [t[2] for t in terms],
        )
        cts: list[bytes] = []
        for vector in vectors:
            for start in range(0, len(vector), per):
                chunk = vector[start : start + per]
                value = sum(v << (self.w * s) for s, v in enumerate(chunk))
                cts.append(pub.encrypt(value).to_bytes())
        proof = put_blob(keys.paillier_proof)
        self.guard_bytes = len(proof)
        body = n.to_bytes(2, "big") + keys.public_bytes() + proof + b"".join(cts)
        self._reply = frame(MsgType.KEYS, 2, body)
        self.state = State.RUNNING
        self.step = 3

    def first_reply(self) -> bytes:
        return self._reply

    def _step(self, data: bytes) -> bytes | None:
        if self.state is not State.RUNNING:
            raise LocalProtocolError(f"cannot receive in state {self.state.value}")
        step = self.step
        if step == 3:
            reader = Reader(unframe(data, MsgType.MASKED, 3))
            masked = MaskedDifferences.read(
                reader, self.paillier.public_key, self.comparison.masked_count()
            )
            reader.finish()
            reply = frame(MsgType.BITS, 4, self.comparison.decompose(masked).to_bytes())
        elif step == 5:
            reader = Reader(unframe(data, MsgType.TESTS, 5))
            tests = BlindedTests.read(reader, self.dgk.public_key, self.comparison.tests_count())
            reader.finish()
            self.comparison.zero_test(tests)
            inputs = [s for per in self.comparison.shares for s in per]
            inputs.append(int(self.path.everywhere))  # Bob's flag (Layout.outputs)
            self.gates = HeGatesBob(self.circuit, self.dgk, inputs)
            reply = self._next(6)
        else:
            self.gates.finish(unframe(data, MsgType.GATES_OUT, step))
            reply = self._next(step + 1)
        self.step += 2
        return reply

    def _next(self, step: int) -> bytes:
        if self.gates.level < self.gates.depth:
            return frame(MsgType.GATES_IN, step, self.gates.offer())
        self.state = State.DONE
        return frame(MsgType.OPEN, step, self.gates.open())
