"""The compact suite's public side: the offer in the hello, the plan of a run, its sizes.

Everything here follows from public values (m, n, the grid's range, the digit width, the OT
setup's parameters): the sub-protocols' shapes, the boolean circuit (:func:`make_plan`) and
every message's size before a run starts (:func:`message_sizes`), which the companion's
fail-safe turns into airtime.  The machines that run the plan are in :mod:`.suite_compact`.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

from .circuit import Circuit
from .encoding import Reader
from .errors import RemoteProtocolError
from .gmw import plan_groups, rot_count, rounds
from .grid import GridSpec
from .intersection import Kind, Layout
from .millionaire import (
    DEFAULT_DIGIT_BITS,
    MAX_DIGIT_BITS,
    Node,
    build_tree,
)
from .millionaire import Shape as LeafShape
from .ot.extension import (
    correction_size,
)
from .ot.setup import (
    DEFAULT_BLOCK_BITS,
    DEFAULT_SECURITY,
    MAX_BLOCK_BITS,
    SECURITY_LEVELS,
    SETUP_ID_SIZE,
    chooser_message_size,
    holder_message_size,
    split_blocks,
)
from .pathcircuit import Orient, Proj
from .products import Shape as ProductShape
from .wire import NONCE_SIZE

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
