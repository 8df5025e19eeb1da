"""The compact suite's public side: the offer in the hello, the plan of a run, its sizes.

Everything here follows from public values (m, n, the grid's range, the digit width, the OT
setup's parameters): the sub-protocols' shapes, the boolean circuit (:func:`make_plan`) and
every message's size before a run starts (:func:`message_sizes`), which the companion's
fail-safe turns into airtime.  The machines that run the plan are in :mod:`protocol.compact.suite`.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from dataclasses import dataclass

from protocol.circuits.boolean import Circuit
from protocol.circuits.paths import Orient, Proj, Range
from protocol.compact.gmw import plan_groups, rot_count, rounds
from protocol.compact.millionaire import (
    DEFAULT_DIGIT_BITS,
    MAX_DIGIT_BITS,
    Node,
    build_tree,
)
from protocol.compact.millionaire import Shape as LeafShape
from protocol.compact.products import Shape as ProductShape
from protocol.errors import RemoteProtocolError
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import CROSSING, SEPARATION_SIZE, VolumeSpec
from protocol.messages import NONCE_SIZE
from protocol.ot.extension import (
    correction_size,
)
from protocol.ot.setup import (
    DEFAULT_BLOCK_BITS,
    DEFAULT_SECURITY,
    MAX_BLOCK_BITS,
    SECURITY_LEVELS,
    SETUP_ID_SIZE,
    chooser_message_size,
    holder_message_size,
    split_blocks,
)
from protocol.run import Kind, Layout, Wires
from protocol.wire.encoding import Reader

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


class Test(enum.Enum):
    """What one compared value is (:mod:`protocol.geo.volumes` for the geometry).  Alice holds
    every threshold; Bob's own parameters (his segments' R'_k and L_k) shift his share."""

    O1 = "o1"  # orient(A_i, A_i+1, B_k): [>= 1] with EQ; capsules: also [>= -R_i],
    # [>= R_i + 1], and no EQ (the crossing needs only P there)
    T = "t"  # projection of B_k on Alice's segment i: [>= 0], [>= T_i + 1]
    O3 = "o3"  # orient(B_k, B_k+1, A_j): [>= 1] with EQ (no EQ with capsules)
    O3_LOW = "o3-low"  # O3 + R'_k: [>= 0]
    O3_HIGH = "o3-high"  # O3 - R'_k - 1: [>= 0] (its negation: O3 <= R'_k)
    T3 = "t3"  # (A_j - B_k) . d_k: [>= 0]
    T3_HIGH = "t3-high"  # T3 - L_k - 1: [>= 0] (its negation: T3 <= L_k)
    D = "d"  # |A_j - B_k|^2: [>= r^2 + 1] (its negation: within r)
    BAND_LOW = "band-low"  # b_hi - a_lo + v: [>= 0]
    BAND_HIGH = "band-high"  # a_hi + v - b_lo: [>= 0]
    TIME_LOW = "time-low"  # b_hi - a_lo: [>= 0]
    TIME_HIGH = "time-high"  # a_hi - b_lo: [>= 0]


_FORM_TESTS = {
    Kind.O1: (Test.O1,),
    Kind.T: (Test.T,),
    Kind.O3: (Test.O3,),
    Kind.T3: (Test.T3, Test.T3_HIGH),
    Kind.D: (Test.D,),
}
_PAIR_TESTS = ((Test.BAND_LOW, Test.BAND_HIGH), (Test.TIME_LOW, Test.TIME_HIGH))


@dataclass(frozen=True, slots=True)
class Compared:
    """One compared value of a run: a form's (``form``: its position in the layout) or a
    segment pair's band or window (``pair``: its index in :meth:`Layout.pairs`)."""

    test: Test
    index: int  # the form's position, or the pair's index
    bits: int
    thresholds: int

    @property
    def from_form(self) -> bool:
        return self.test not in _PAIR_SET


_PAIR_SET = frozenset(t for tests in _PAIR_TESTS for t in tests)


@dataclass(frozen=True)
class Plan:
    """Everything public about a run: shapes of the sub-protocols, the circuit, OT usage."""

    layout: Layout
    volumes: VolumeSpec  # the run's (separation: the larger of both parties')
    l: int
    compared: tuple[Compared, ...]
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


def _compared(layout: Layout, volumes: VolumeSpec, l: int) -> list[Compared]:
    capsules = layout.capsules
    out: list[Compared] = []
    for position, (kind, _, _) in enumerate(layout.values):
        tests = _FORM_TESTS[kind]
        if kind is Kind.O3 and capsules:
            tests = (Test.O3, Test.O3_LOW, Test.O3_HIGH)
        for test in tests:
            count = {Test.T: 2, Test.O1: 3 if capsules else 1}.get(test, 1)
            out.append(Compared(test, position, l, count))
    widths = (volumes.band_bits(volumes.separation.vertical), volumes.window_bits())
    for tests, on, bits in zip(_PAIR_TESTS, (layout.bands, layout.windows), widths, strict=True):
        if on:
            out += [Compared(t, p, bits, 1) for p in range(len(layout.pairs())) for t in tests]
    return out


def make_plan(m: int, n: int, grid: GridSpec, digit_bits: int, volumes: VolumeSpec) -> Plan:
    """The public plan of an m x n run on ``grid`` with the run's ``volumes`` (its separation
    the larger of both parties')."""
    capsules = volumes.separation.horizontal > 0
    layout = Layout(m, n, capsules=capsules, bands=volumes.bands, windows=volumes.windows)
    l = grid.l
    products = _product_shape(layout, n, l, grid.range)
    compared = _compared(layout, volumes, l)
    leaves = LeafShape.of([c.bits for c in compared], digit_bits, [c.thresholds for c in compared])
    circuit = Circuit()
    ge, eq = _comparison_wires(circuit, compared, leaves, capsules)
    wires = _form_wires(circuit, layout, ge, eq, capsules)
    layout.outputs(
        circuit,
        wires,
        bands=_pair_ranges(layout, ge, _PAIR_TESTS[0], layout.bands),
        windows=_pair_ranges(layout, ge, _PAIR_TESTS[1], layout.windows),
    )
    rots = (products.rots, leaves.rots, rot_count(circuit))
    return Plan(layout, volumes, l, tuple(compared), products, leaves, circuit, rots)


_Key = tuple[Test, int]  # a compared value: its test and index


def _product_shape(layout: Layout, n: int, l: int, r: int) -> ProductShape:
    """The products' shape: Bob's values and, per form, the two values it multiplies."""
    coord_bits, delta_bits = (2 * r).bit_length(), (4 * r).bit_length()
    # Bob's values: X'_k, Y'_k for k <= n, then dX'_k, dY'_k for k < n.
    value_bits = (coord_bits,) * (2 * (n + 1)) + (delta_bits,) * (2 * n)
    terms: list[tuple[int, int]] = []
    for position, (kind, _, k) in enumerate(layout.values):
        first = 2 * (n + 1) + 2 * k if kind in (Kind.O3, Kind.T3) else 2 * k
        terms += [(first, position), (first + 1, position)]
    return ProductShape(l + 1, value_bits, tuple(terms), len(layout.values))


def _comparison_wires(
    circuit: Circuit, compared: list[Compared], leaves: LeafShape, capsules: bool
) -> tuple[dict[_Key, list[int]], dict[_Key, int]]:
    """The comparison trees of every compared value: its [>= threshold] wires, and the EQ
    wire where the exact crossing needs it."""
    ge: dict[_Key, list[int]] = {}
    eq: dict[_Key, int] = {}
    for c, widths in zip(compared, leaves.digits, strict=True):
        # EQ of the first threshold, [v = 0]: for the exact crossing only
        exact = c.test in (Test.O1, Test.O3) and not capsules
        roots = []
        for t in range(c.thresholds):
            nodes = [Node(circuit.input(), circuit.input()) for _ in widths]
            roots.append(build_tree(circuit, nodes, need_eq=exact and t == 0))
        highs = [circuit.input() for _ in range(c.thresholds)]
        ge[c.test, c.index] = [
            circuit.xor(root.gt, high) for root, high in zip(roots, highs, strict=True)
        ]
        if exact:
            root_eq = roots[0].eq
            assert root_eq is not None
            eq[c.test, c.index] = root_eq
    return ge, eq


def _form_wires(
    circuit: Circuit,
    layout: Layout,
    ge: dict[_Key, list[int]],
    eq: dict[_Key, int],
    capsules: bool,
) -> list[Wires]:
    """The path circuit's input wires of every form, from its comparison wires."""
    wires: list[Wires] = []
    for position, (kind, _, _) in enumerate(layout.values):
        if kind is Kind.O1:
            o1 = ge[Test.O1, position]
            near = Range(o1[1], circuit.not_(o1[2])) if capsules else None
            wires.append(Wires(orient=Orient(o1[0], eq.get((Test.O1, position), -1)), near=near))
        elif kind is Kind.T:
            low, high = ge[Test.T, position]
            wires.append(Wires(proj=Proj(circuit.not_(low), high)))
        elif kind is Kind.O3:
            near = None
            if capsules:
                high = ge[Test.O3_HIGH, position][0]
                near = Range(ge[Test.O3_LOW, position][0], circuit.not_(high))
            orient = Orient(ge[Test.O3, position][0], eq.get((Test.O3, position), -1))
            wires.append(Wires(orient=orient, near=near))
        elif kind is Kind.T3:
            high = ge[Test.T3_HIGH, position][0]
            wires.append(Wires(near=Range(ge[Test.T3, position][0], circuit.not_(high))))
        else:
            wires.append(Wires(disc=circuit.not_(ge[Test.D, position][0])))
    return wires


def _pair_ranges(
    layout: Layout, ge: dict[_Key, list[int]], tests: tuple[Test, Test], on: bool
) -> list[Range] | None:
    """The band (window) wires of every segment pair, or None when the run has none."""
    if not on:
        return None
    low, high = tests
    return [Range(ge[low, p][0], ge[high, p][0]) for p in range(len(layout.pairs()))]


def message_sizes(
    m: int,
    n: int,
    grid: GridSpec,
    *,
    digit_bits: int = DEFAULT_DIGIT_BITS,
    fresh_setup: bool = False,
    block_bits: int = DEFAULT_BLOCK_BITS,
    ot_security: int = DEFAULT_SECURITY,
    volumes: VolumeSpec = CROSSING,
) -> list[tuple[bool, int]]:
    """(sent by Alice, frame bytes) of every message of an m x n run (padded sizes) with the
    run's ``volumes`` (the larger separation of both parties), computed from public values
    alone: what a run will cost on the radio before it starts."""
    return list(
        _message_sizes(m, n, grid.range, digit_bits, fresh_setup, block_bits, ot_security, volumes)
    )


@functools.lru_cache(maxsize=128)
def _message_sizes(
    m: int,
    n: int,
    range_: int,
    digit_bits: int,
    fresh_setup: bool,
    block_bits: int,
    ot_security: int,
    volumes: VolumeSpec,
) -> tuple[tuple[bool, int], ...]:
    """message_sizes, cached: the plan (tens to hundreds of ms) depends on the sizes, the
    grid's range and the volumes only, and a companion asks for the same few again and
    again."""
    plan = make_plan(m, n, GridSpec(range=range_), digit_bits, volumes)
    fresh = Offer(digit_bits, None, block_bits, ot_security)
    blocks = fresh.blocks
    offer = (
        dataclasses.replace(fresh, points=bytes(holder_message_size(ot_security)))
        if fresh_setup
        else Offer(digit_bits, bytes(SETUP_ID_SIZE))
    )
    header = 8
    fields = 2 + 17 + 2 + 4 + 2  # suite and kappa, grid, m, horizon, n
    hello = header + fields + len(volumes.to_bytes()) + NONCE_SIZE + 2 + len(offer.to_bytes())
    offer_size = (
        2
        + NONCE_SIZE
        + SEPARATION_SIZE
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
