"""The compact suite: the path protocol on oblivious transfer (the default).

Messages (step numbers in the frame header), with w-bit digits and D AND levels:

====  =========  =====================================================================
 1    A -> B     HELLO: grid, m, horizon, nonce; the cached setup's id, or kappa (112)
                 base-OT points for a fresh setup (:mod:`protocol.ot.setup`)
 2    B -> A     OFFER: n, nonce; (fresh setup: A and the GGM corrections); the run's OT
                 extension (15 bits per OT); Bob's value bits XOR his choice bits
 3    A -> B     PRODUCTS: every compared value as shares mod 2^(l+1) (:mod:`.products`)
 4    B -> A     DIGITS: the digit bits of Bob's shares XOR his choice bits
 5    A -> B     TABLES: the comparison leaves (:mod:`.millionaire`), the first circuit round
 6..  either     ROUND: openings of the next AND level (:mod:`.gmw`); the last, Bob's,
                 carries his shares of Alice's m result bits
====  =========  =====================================================================

*Values as shares.*  Bob's non-negative inputs are his coordinates shifted by R (X + R,
Y + R in [0, 2 R]) and segment deltas shifted by 2 R; Alice multiplies them by her
coefficients (:func:`protocol.geometry.orient_coefficients`, :func:`~.geometry.projection_key`,
her vertices for O3) and moves the shifts into her constant.  Each value v = a + b mod 2^L,
L = l + 1, with a Alice's share and b Bob's.

*Sign bits.*  For threshold theta, z = v - theta + 2^l lies in (0, 2^(l+1)), so [v >= theta] is
bit l of z.  With A = a - theta + 2^l and B = b (mod 2^(l+1)), bit l of A + B is
A_l xor B_l xor carry, and carry = [B mod 2^l > 2^l - 1 - (A mod 2^l)]: a millionaires'
comparison of Bob's l low bits with Alice's complement.  Its EQ output says
A + B = 2^l - 1 (mod 2^l), i.e. v = theta - 1.  Orientation values use theta = 1: P = [v >= 1]
and Z = EQ = [v = 0].  Projections use theta = 0 (L = not [t >= 0]) and theta = T + 1
(H = [t > T]); the thresholds are Alice's, so Bob cannot tell them apart.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import secrets
from collections.abc import MutableMapping, Sequence
from dataclasses import dataclass

from .circuit import Circuit
from .encoding import Reader
from .errors import InputRangeError, LocalProtocolError, RemoteProtocolError, UnknownSetupError
from .geometry import BobPath, Point, orient_coefficients, pad_path, projection_key
from .gmw import Gmw, plan_groups, rot_count, rounds
from .grid import GridSpec
from .intersection import AliceSide, BobSide, Kind, Layout, Limits, State
from .millionaire import (
    DEFAULT_DIGIT_BITS,
    MAX_DIGIT_BITS,
    LeavesAlice,
    LeavesBob,
    Node,
    build_tree,
)
from .millionaire import Shape as LeafShape
from .ot.extension import (
    ChooserRots,
    HolderRots,
    chooser_extend,
    correction_size,
    holder_extend,
)
from .ot.setup import (
    DEFAULT_BLOCK_BITS,
    DEFAULT_SECURITY,
    MAX_BLOCK_BITS,
    SECURITY_LEVELS,
    SETUP_ID_SIZE,
    ChooserSetup,
    HolderSetup,
    HolderSetupStart,
    chooser_message_size,
    chooser_setup,
    holder_message_size,
    split_blocks,
)
from .pathcircuit import Orient, Proj
from .products import ProductsAlice, ProductsBob
from .products import Shape as ProductShape
from .wire import NONCE_SIZE, Hello, MsgType, Suite, frame, unframe

CACHED, FRESH = 0, 1


# --------------------------------------------------------------------------- the offer


@dataclass(frozen=True, slots=True)
class Offer:
    """The compact suite's part of the hello: digit bits, and the OT setup."""

    digit_bits: int
    setup_id: bytes | None  # a cached setup
    block_bits: int = DEFAULT_BLOCK_BITS  # fresh setup: at most this many bits per block
    security: int = DEFAULT_SECURITY  # fresh setup: kappa, the bits of Delta
    points: bytes = b""  # fresh setup: the base-OT receiver message

    @property
    def blocks(self) -> tuple[int, ...]:
        return split_blocks(self.block_bits, self.security)

    def to_bytes(self) -> bytes:
        head = bytes([self.digit_bits])
        if self.setup_id is not None:
            return head + bytes([CACHED]) + self.setup_id
        return head + bytes([FRESH, self.block_bits, self.security]) + self.points

    @classmethod
    def from_bytes(cls, data: bytes) -> Offer:
        reader = Reader(data)
        digit_bits = reader.uint(1)
        if not 1 <= digit_bits <= MAX_DIGIT_BITS:
            raise RemoteProtocolError(f"digits of {digit_bits} bits are not supported")
        mode = reader.uint(1)
        if mode == CACHED:
            offer = cls(digit_bits, reader.take(SETUP_ID_SIZE))
        elif mode == FRESH:
            block_bits, security = reader.uint(1), reader.uint(1)
            if security not in SECURITY_LEVELS or not 1 <= block_bits <= MAX_BLOCK_BITS:
                raise RemoteProtocolError(
                    f"OT setup with {security}-bit Delta in {block_bits}-bit blocks"
                )
            points = reader.take(holder_message_size(security))
            offer = cls(digit_bits, None, block_bits, security, points)
        else:
            raise RemoteProtocolError(f"unknown OT setup mode {mode}")
        reader.finish()
        return offer


# --------------------------------------------------------------------------- the plan


@dataclass(frozen=True)
class Plan:
    """Everything public about a run: shapes of the sub-protocols, the circuit, OT usage."""

    layout: Layout
    l: int
    products: ProductShape
    leaves: LeafShape
    circuit: Circuit
    rots: tuple[int, int, int]  # OTs for products, leaves, triples

    @property
    def total_rots(self) -> int:
        return sum(self.rots)

    def slices(self) -> tuple[slice, slice, slice]:
        a, b, c = self.rots
        return slice(0, a), slice(a, a + b), slice(a + b, a + b + c)


def make_plan(m: int, n: int, grid: GridSpec, digit_bits: int) -> Plan:
    layout = Layout(m, n)
    l, r = grid.l, grid.range
    coord_bits, delta_bits = (2 * r).bit_length(), (4 * r).bit_length()
    # Bob's values: X'_k, Y'_k for k <= n, then dX'_k, dY'_k for k < n.
    value_bits = (coord_bits,) * (2 * (n + 1)) + (delta_bits,) * (2 * n)
    terms: list[tuple[int, int]] = []
    for position, (kind, _, k) in enumerate(layout.values):
        if kind is Kind.O3:
            terms += [(2 * (n + 1) + 2 * k, position), (2 * (n + 1) + 2 * k + 1, position)]
        else:
            terms += [(2 * k, position), (2 * k + 1, position)]
    products = ProductShape(l + 1, value_bits, tuple(terms), len(layout.values))
    counts = [2 if kind is Kind.T else 1 for kind, _, _ in layout.values]
    leaves = LeafShape.of(l, digit_bits, counts)
    circuit = Circuit()
    orient: list[Orient] = []
    proj: list[Proj] = []
    for count in counts:
        roots = []
        for _ in range(count):
            nodes = [Node(circuit.input(), circuit.input()) for _ in leaves.widths]
            roots.append(build_tree(circuit, nodes, need_eq=count == 1))
        highs = [circuit.input() for _ in range(count)]
        ge = [circuit.xor(root.gt, high) for root, high in zip(roots, highs, strict=True)]
        if count == 1:
            eq = roots[0].eq
            assert eq is not None
            orient.append(Orient(ge[0], eq))
            proj.append(Proj(-1, -1))
        else:
            orient.append(Orient(-1, -1))
            proj.append(Proj(circuit.not_(ge[0]), ge[1]))
    layout.outputs(circuit, orient, proj)
    rots = (products.rots, leaves.rots, rot_count(circuit))
    return Plan(layout, l, products, leaves, circuit, rots)


def _run_nonce(alice: bytes, bob: bytes, setup_id: bytes) -> bytes:
    return hashlib.blake2b(
        alice + bob + setup_id, digest_size=32, person=b"pdc/run/nonce/v1"
    ).digest()


def _circuit_inputs(
    plan: Plan, leaf_shares: list[list[list[tuple[int, int]]]], highs: list[list[int]], flag: int
) -> list[int]:
    """Input shares in the circuit's wire order (see :func:`make_plan`); Bob's flag last."""
    out: list[int] = []
    for per_value, high in zip(leaf_shares, highs, strict=True):
        for per_threshold in per_value:
            for gt, eq in per_threshold:
                out += [gt, eq]
        out += high
    return [*out, flag]


# --------------------------------------------------------------------------- Alice


class CompactAlice(AliceSide):
    """Alice's side of the compact suite."""

    def __init__(
        self,
        path: Sequence[Point],
        grid: GridSpec,
        *,
        setup: HolderSetup | None,
        limits: Limits,
        horizon_m: int = 0,
        digit_bits: int | None = None,
        block_bits: int = DEFAULT_BLOCK_BITS,
        ot_security: int = DEFAULT_SECURITY,
    ) -> None:
        self.segments = len(path) - 1
        self.m = limits.padded(self.segments)
        self.path = pad_path(path, self.m)
        self.grid, self.limits, self.horizon_m = grid, limits, horizon_m
        self.digit_bits = digit_bits or DEFAULT_DIGIT_BITS
        if not 1 <= self.digit_bits <= MAX_DIGIT_BITS:
            raise InputRangeError(f"digits of 1..{MAX_DIGIT_BITS} bits")
        self.setup = setup
        self._offer = Offer(self.digit_bits, None, block_bits, ot_security)
        self._fresh = HolderSetupStart(self._offer.blocks) if setup is None else None
        self.nonce = secrets.token_bytes(NONCE_SIZE)
        self.state = State.START
        self.step = 2
        self._hits: list[bool] = []

    def start(self) -> bytes:
        if self.state is not State.START:
            raise LocalProtocolError("already started")
        if self.setup is not None:
            offer = Offer(self.digit_bits, self.setup.setup_id)
        else:
            assert self._fresh is not None
            offer = dataclasses.replace(self._offer, points=self._fresh.message())
        hello = Hello(
            Suite.COMPACT, 0, self.grid, self.m, self.horizon_m, self.nonce, offer.to_bytes()
        )
        self.state = State.RUNNING
        return hello.to_bytes()

    def _step(self, data: bytes) -> bytes | None:
        if self.state is not State.RUNNING:
            raise LocalProtocolError(f"cannot receive in state {self.state.value}")
        step = self.step
        reply: bytes | None
        if step == 2:
            reply = self._on_offer(unframe(data, MsgType.OFFER, 2))
        elif step == 4:
            reply = self._on_digits(unframe(data, MsgType.DIGITS, 4))
        else:
            reply = self._on_round(unframe(data, MsgType.ROUND, step))
        self.step += 2
        return reply

    # message 2 -> 3
    def _on_offer(self, body: bytes) -> bytes:
        reader = Reader(body)
        self.n = self.limits.peer_size(reader.uint(2))
        bob_nonce = reader.take(NONCE_SIZE)
        if self._fresh is not None:
            self.setup = self._fresh.finish(reader.take(chooser_message_size(self._fresh.blocks)))
        assert self.setup is not None
        self.plan = plan = make_plan(self.m, self.n, self.grid, self.digit_bits)
        nonce = _run_nonce(self.nonce, bob_nonce, self.setup.setup_id)
        extension = reader.take(correction_size(self.setup.blocks, plan.total_rots))
        flips = reader.take(plan.products.correction_size())
        reader.finish()
        rots = holder_extend(self.setup, nonce, plan.total_rots, extension)
        p, q, r = plan.slices()
        self._leaf_rots = HolderRots(rots.keys0[q], rots.keys1[q])
        self._triple_rots = HolderRots(rots.keys0[r], rots.keys1[r])
        multipliers, constants = self._multipliers()
        products = ProductsAlice(
            plan.products, multipliers, HolderRots(rots.keys0[p], rots.keys1[p])
        )
        message, shares = products.message(flips)
        modulus = 1 << (plan.l + 1)
        self._shares = [(s + c) % modulus for s, c in zip(shares, constants, strict=True)]
        return frame(MsgType.PRODUCTS, 3, message)

    def _multipliers(self) -> tuple[list[int], list[int]]:
        """Alice's coefficient per product and constant per value (Bob's shifts folded in)."""
        r = self.grid.range
        a = self.path
        orient_rows = [orient_coefficients(a[i], a[i + 1]) for i in range(self.m)]
        proj_rows = [projection_key(a[i], a[i + 1], self.grid.span) for i in range(self.m)]
        multipliers: list[int] = []
        constants: list[int] = []
        for kind, row, _ in self.plan.layout.values:
            if kind is Kind.O1:
                al, be, ga = orient_rows[row]
                multipliers += [al, be]
                constants.append(ga - (al + be) * r)
            elif kind is Kind.T:
                ex, ey, off, _ = proj_rows[row]
                multipliers += [ex, ey]
                constants.append(off - (ex + ey) * r)
            else:
                ax, ay = a[row]
                multipliers += [ay, -ax]
                constants.append(-2 * r * (ay - ax))
        self._t_max = [t for *_, t in proj_rows]
        return multipliers, constants

    def _thresholds(self) -> tuple[list[list[int]], list[list[int]]]:
        """Per value and threshold: the l-bit comparison target and Alice's high bit."""
        l = self.plan.l
        top, low = 1 << (l + 1), (1 << l) - 1
        targets: list[list[int]] = []
        highs: list[list[int]] = []
        for (kind, row, _), share in zip(self.plan.layout.values, self._shares, strict=True):
            thetas = [0, self._t_max[row] + 1] if kind is Kind.T else [1]
            shifted = [(share - theta + (1 << l)) % top for theta in thetas]
            targets.append([low - (s & low) for s in shifted])
            highs.append([s >> l for s in shifted])
        return targets, highs

    # message 4 -> 5
    def _on_digits(self, body: bytes) -> bytes:
        targets, highs = self._thresholds()
        leaves = LeavesAlice(self.plan.leaves, targets, self._leaf_rots)
        tables, shares = leaves.tables(body)
        self.gmw = Gmw(
            self.plan.circuit,
            alice=True,
            rots=self._triple_rots,
            inputs=_circuit_inputs(self.plan, shares, highs, 0),
        )
        return frame(MsgType.TABLES, 5, tables + self.gmw.send())

    # messages 6, 8, ... -> 7, 9, ...
    def _on_round(self, body: bytes) -> bytes | None:
        self.gmw.receive(body)
        if self.gmw.finished:
            self._hits = [bool(b) for b in self.gmw.outputs()[: self.segments]]
            self.state = State.DONE
            return None
        return frame(MsgType.ROUND, self.step + 1, self.gmw.send())


# --------------------------------------------------------------------------- Bob


class CompactBob(BobSide):
    """Bob's side of the compact suite, created from Alice's hello."""

    def __init__(
        self,
        hello: Hello,
        path: BobPath,
        setups: MutableMapping[bytes, ChooserSetup],
    ) -> None:
        n = path.segments
        self.hello, self.path, self.n, self.m = hello, path, n, hello.m
        self.grid = hello.grid
        offer = Offer.from_bytes(hello.offer)
        self.plan = make_plan(self.m, n, self.grid, offer.digit_bits)
        setup_reply = b""
        if offer.setup_id is not None:
            found = setups.get(offer.setup_id)
            if found is None:
                raise UnknownSetupError("unknown OT setup (start a fresh one)")
            self.setup = found
        else:
            self.setup, setup_reply = chooser_setup(offer.points, offer.blocks)
            setups[self.setup.setup_id] = self.setup
        nonce_b = secrets.token_bytes(NONCE_SIZE)
        nonce = _run_nonce(hello.nonce, nonce_b, self.setup.setup_id)
        extension, rots = chooser_extend(self.setup, nonce, self.plan.total_rots)
        p, q, r = self.plan.slices()
        self._leaf_rots = ChooserRots(rots.choices[q], rots.keys[q])
        self._triple_rots = ChooserRots(rots.choices[r], rots.keys[r])
        self.products = ProductsBob(
            self.plan.products, self._values(), ChooserRots(rots.choices[p], rots.keys[p])
        )
        self._reply = frame(
            MsgType.OFFER,
            2,
            n.to_bytes(2, "big") + nonce_b + setup_reply + extension + self.products.corrections(),
        )
        self.state = State.RUNNING
        self.step = 3

    def first_reply(self) -> bytes:
        return self._reply

    def _values(self) -> list[int]:
        r = self.grid.range
        values = [c + r for point in self.path.points for c in point]
        for k in range(self.n):
            dx, dy, _ = self.path.line(k)
            values += [dx + 2 * r, dy + 2 * r]
        return values

    def _step(self, data: bytes) -> bytes | None:
        if self.state is not State.RUNNING:
            raise LocalProtocolError(f"cannot receive in state {self.state.value}")
        step = self.step
        if step == 3:
            reply = self._on_products(unframe(data, MsgType.PRODUCTS, 3))
        elif step == 5:
            reply = self._on_tables(unframe(data, MsgType.TABLES, 5))
        else:
            reply = self._on_round(unframe(data, MsgType.ROUND, step))
        self.step += 2
        return reply

    # message 3 -> 4
    def _on_products(self, body: bytes) -> bytes:
        shares = self.products.shares(body)
        l = self.plan.l
        top = 1 << (l + 1)
        constants = [
            self.path.line(k)[2] if kind is Kind.O3 else 0 for kind, _, k in self.plan.layout.values
        ]
        values = [(s + c) % top for s, c in zip(shares, constants, strict=True)]
        self._highs = [v >> l for v in values]
        self.leaves = LeavesBob(
            self.plan.leaves, [v & ((1 << l) - 1) for v in values], self._leaf_rots
        )
        return frame(MsgType.DIGITS, 4, self.leaves.corrections())

    # message 5 -> 6
    def _on_tables(self, body: bytes) -> bytes:
        size = self.plan.leaves.table_size()
        shares = self.leaves.shares(body[:size])
        counts = self.plan.leaves.thresholds
        highs = [[h] * count for h, count in zip(self._highs, counts, strict=True)]
        self.gmw = Gmw(
            self.plan.circuit,
            alice=False,
            rots=self._triple_rots,
            inputs=_circuit_inputs(self.plan, shares, highs, int(self.path.everywhere)),
        )
        self.gmw.receive(body[size:])
        return self._send()

    def _on_round(self, body: bytes) -> bytes:
        self.gmw.receive(body)
        return self._send()

    def _send(self) -> bytes:
        message = frame(MsgType.ROUND, self.step + 1, self.gmw.send())
        if self.gmw.finished:
            self.state = State.DONE
        return message


def message_sizes(
    m: int,
    n: int,
    grid: GridSpec,
    *,
    digit_bits: int = DEFAULT_DIGIT_BITS,
    fresh_setup: bool = False,
    block_bits: int = DEFAULT_BLOCK_BITS,
    ot_security: int = DEFAULT_SECURITY,
) -> list[tuple[bool, int]]:
    """(sent by Alice, frame bytes) of every message of an m x n run (padded sizes), computed
    from public values alone: what a run will cost on the radio before it starts."""
    return list(_message_sizes(m, n, grid.range, digit_bits, fresh_setup, block_bits, ot_security))


@functools.lru_cache(maxsize=128)
def _message_sizes(
    m: int,
    n: int,
    range_: int,
    digit_bits: int,
    fresh_setup: bool,
    block_bits: int,
    ot_security: int,
) -> tuple[tuple[bool, int], ...]:
    """message_sizes, cached: the plan (tens to hundreds of ms) depends on the sizes and the
    grid's range only, and a companion asks for the same few again and again."""
    plan = make_plan(m, n, GridSpec(range=range_), digit_bits)
    fresh = Offer(digit_bits, None, block_bits, ot_security)
    blocks = fresh.blocks
    offer = (
        dataclasses.replace(fresh, points=bytes(holder_message_size(ot_security)))
        if fresh_setup
        else Offer(digit_bits, bytes(SETUP_ID_SIZE))
    )
    header = 8
    hello = header + 2 + 17 + 2 + 4 + NONCE_SIZE + 2 + len(offer.to_bytes())
    offer_size = (
        2
        + NONCE_SIZE
        + (chooser_message_size(blocks) if fresh_setup else 0)
        + correction_size(blocks, plan.total_rots)
        + plan.products.correction_size()
    )
    groups = plan_groups(plan.circuit)
    corrections = sum(len(g.gates) - 1 for level in groups for g in level)
    outputs = len(plan.circuit.outputs)
    rounds_ = []
    for step in rounds(plan.circuit.depth):
        bits = sum(sum(1 + len(g.gates) for g in groups[level]) for level in step.levels)
        bits += corrections if step.corrections else 0
        bits += outputs if step.outputs else 0
        rounds_.append((step.alice_sends, (bits + 7) // 8))
    sizes = [
        (True, hello),
        (False, header + offer_size),
        (True, header + plan.products.message_size()),
        (False, header + plan.leaves.correction_size()),
        (True, header + plan.leaves.table_size() + rounds_[0][1]),
    ]
    sizes += [(alice, header + size) for alice, size in rounds_[1:]]
    return tuple(sizes)
