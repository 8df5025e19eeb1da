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
import hashlib
import secrets
from collections.abc import MutableMapping, Sequence

from .compact_plan import Offer, Plan, make_plan
from .encoding import Reader
from .errors import InputRangeError, LocalProtocolError, UnknownSetupError
from .geometry import BobPath, Point, orient_coefficients, pad_path, projection_key
from .gmw import Gmw
from .grid import GridSpec
from .intersection import AliceSide, BobSide, Kind, Limits, State
from .millionaire import (
    DEFAULT_DIGIT_BITS,
    MAX_DIGIT_BITS,
    LeavesAlice,
    LeavesBob,
)
from .ot.extension import (
    ChooserRots,
    HolderRots,
    check_bytes,
    chooser_extend,
    correction_size,
    holder_extend,
)
from .ot.setup import (
    DEFAULT_BLOCK_BITS,
    DEFAULT_SECURITY,
    ChooserSetup,
    HolderSetup,
    HolderSetupStart,
    chooser_message_size,
    chooser_setup,
)
from .products import ProductsAlice, ProductsBob
from .wire import NONCE_SIZE, Hello, MsgType, Suite, frame, unframe

__all__ = ["CompactAlice", "CompactBob"]


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
        self.guard_bytes = check_bytes(self.setup.blocks, plan.total_rots)
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
        self.guard_bytes = check_bytes(self.setup.blocks, self.plan.total_rots)
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
